#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Every nodelet's topics and parameters in docs/nodes.md are the code's.

usage: check_nodes_doc.py [--root DIR] [--xunit FILE.xml] [--self-test]

For each nodelet of nodelet_plugins.xml (a `## skin3d/<name>` section in docs/nodes.md, ROS-wiki form):
  - parameters: the `~name` rows of its Parameters table are exactly the private parameters its code reads
    (pnh.param / getParam / hasParam with a literal key in the files that hold its runner), plus, where the node
    reads a whole option table, every key of that table's config file (config/frontend.yaml,
    config/induration.yaml); the eskf_slam keys of config/slam.yaml are the table of docs/slam.md.
    (That each config file holds exactly its option table's keys with the code's defaults is checked by the
    gtests ConfigFileListsEveryKeyWithTheCodeDefault / ConfigFileListsExactlyTheKeysWithTheCodeDefaults.)
  - topics: every topic name in its Subscribed / Published bullets appears in a subscribe / advertise call of
    its code, and every topic its code subscribes or advertises is documented.
--self-test first checks the readers on small known texts. Exit status 1 when something disagrees.
"""
import argparse
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from xunit import write_xunit  # noqa: E402

# nodelet -> the files that hold its parameters and topics (its runner), and its option tables: (config file,
# the doc whose table lists that file's keys, or None: the node's own Parameters table)
NODES = {
    "stereo_capture": (["src/ros/capture_node.cpp"], []),
    "stereo_rectify": (["src/ros/rectify_runner.cpp"], []),
    "stereo_front_end": (["src/ros/front_end_runner.cpp"], [("config/frontend.yaml", None)]),
    "eskf_slam": (["src/ros/slam_runner.cpp", "src/ros/slam_messages.cpp"], [("config/slam.yaml", "docs/slam.md")]),
    "stereo_design": (["src/ros/design_node.cpp"], []),
    "induration": (["src/ros/induration_runner.cpp"], [("config/induration.yaml", "docs/induration.md")]),
    "site_fusion": (["src/ros/site_runner.cpp"], [("config/induration.yaml", "docs/induration.md"),
                                                  ("config/site.yaml", "docs/site.md")]),
}
# runners added later register here by file name pattern (src/ros/<name>_runner.cpp); see find_files()

PARAM_RE = re.compile(r'\bp?nh_?\s*(?:\.|->)\s*(?:param|getParam|hasParam|getParamCached)\s*(?:<[^>()]*>)?\s*\(\s*"([^"]+)"')
CALL_RE = re.compile(r'\b((?:advertise|subscribe)\w*)\s*(?:<[^;{}]*?>)?\s*\(([^;]*?)\)\s*;', re.S)
STRING_RE = re.compile(r'"([^"\\]*)"')
# ros_conv::imageTransportParam(pnh) reads ~image_transport; a stereo subscription then also takes image_transport's
# compressed topics (IMAGE/compressed)
TRANSPORT_RE = re.compile(r'\bimageTransportParam\s*\(')
SYNC_RE = re.compile(r'\b\w+\s*(?:\.|->)\s*subscribe\s*\([^;]*?"(image_raw|image_rect)"', re.S)


def strip_comments(text):
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def code_params(texts):
    keys = set()
    for t in texts:
        keys.update(PARAM_RE.findall(strip_comments(t)))
        if TRANSPORT_RE.search(strip_comments(t)):
            keys.add("image_transport")
    return keys


def code_topics(texts):
    topics, services = set(), set()
    for t in texts:
        t = strip_comments(t)
        for kind, args in CALL_RE.findall(t):
            for s in STRING_RE.findall(args)[:1]:  # the name is the call's first string
                if kind == "advertiseService":
                    services.add(s)
                elif re.fullmatch(r"[a-z_]+(/[a-z_]+)+", s):
                    topics.add(s)
                    if kind == "advertiseCamera":  # image_transport: the image and its camera_info
                        topics.add(s.rsplit("/", 1)[0] + "/camera_info")
        for image in SYNC_RE.findall(t):
            for side in ("left", "right"):
                topics.add("stereo/%s/%s" % (side, image))
                topics.add("stereo/%s/camera_info" % side)
                if TRANSPORT_RE.search(t):
                    topics.add("stereo/%s/%s/compressed" % (side, image))
    return topics, services


def doc_sections(text):
    """{nodelet: {"params": set, "topics": set, "services": set}} from docs/nodes.md."""
    out = {}
    for m in re.finditer(r"^## skin3d/(\w+)\n(.*?)(?=^## |\Z)", text, re.S | re.M):
        name, body = m.group(1), m.group(2)
        sec = {"params": set(), "topics": set(), "services": set()}
        for sm in re.finditer(r"^### ([^\n]+)\n(.*?)(?=^### |\Z)", body, re.S | re.M):
            title, content = sm.group(1).strip().lower(), sm.group(2)
            if title == "parameters":
                sec["params"].update(re.findall(r"^\|\s*`~([A-Za-z0-9_]+)`", content, re.M))
            elif title in ("subscribed topics", "published topics"):
                for line in content.splitlines():
                    if line.startswith("- "):
                        head = line.split("(")[0]
                        sec["topics"].update(n for n in re.findall(r"`([^`]+)`", head)
                                             if "/" in n and not n.startswith("~"))
            elif title == "services":
                for line in content.splitlines():
                    if line.startswith("- "):
                        sec["services"].update(n.lstrip("~") for n in re.findall(r"`([^`]+)`", line.split("(")[0]))
        out[name] = sec
    return out


def yaml_keys(path):
    keys = []
    with open(path) as f:
        for line in f:
            m = re.match(r"^([A-Za-z0-9_]+):", line)
            if m:
                keys.append(m.group(1))
    return keys


def table_keys(path):
    with open(path) as f:
        return set(re.findall(r"^\|\s*`([A-Za-z0-9_]+)`", f.read(), re.M))


def find_files(root, name):
    if name in NODES:
        return NODES[name]
    runner = "src/ros/%s_runner.cpp" % name
    if os.path.exists(os.path.join(root, runner)):
        tables = [("config/induration.yaml", None)] if name in ("induration", "dense_stereo") else []
        return [runner], tables
    return None


def check(root):
    results = []
    with open(os.path.join(root, "docs/nodes.md")) as f:
        docs = doc_sections(f.read())
    with open(os.path.join(root, "nodelet_plugins.xml")) as f:
        nodelets = re.findall(r'<class name="skin3d/(\w+)"', f.read())
    for name in nodelets:
        problems = []
        files = find_files(root, name)
        if files is None:
            results.append((name, "no runner file known for skin3d/%s (add it to NODES)" % name))
            continue
        paths, tables = files
        texts = []
        for p in paths:
            with open(os.path.join(root, p)) as f:
                texts.append(f.read())
        doc = docs.get(name)
        if doc is None:
            results.append((name, "docs/nodes.md has no section '## skin3d/%s'" % name))
            continue
        params = code_params(texts)
        for cfg, table_doc in tables:
            keys = set(yaml_keys(os.path.join(root, cfg)))
            if table_doc is None:
                params |= keys
            else:
                missing = keys - table_keys(os.path.join(root, table_doc))
                if missing:
                    problems.append("%s lacks the %s keys %s" % (table_doc, cfg, ", ".join(sorted(missing))))
        if params - doc["params"]:
            problems.append("parameters read by the code but not documented: ~" + ", ~".join(sorted(params - doc["params"])))
        if doc["params"] - params:
            problems.append("parameters documented but not read by the code: ~" + ", ~".join(sorted(doc["params"] - params)))
        topics, services = code_topics(texts)
        if topics - doc["topics"]:
            problems.append("topics of the code not documented: " + ", ".join(sorted(topics - doc["topics"])))
        if doc["topics"] - topics:
            problems.append("topics documented but not in the code: " + ", ".join(sorted(doc["topics"] - topics)))
        if services - doc["services"]:
            problems.append("services of the code not documented: " + ", ".join(sorted(services - doc["services"])))
        results.append((name, "; ".join(problems)))
    return results


def self_test():
    code = '''
      pnh.param("queue_size", q, 5);  // pnh.param("commented", x, 1);
      pnh_.param<std::string>("frame", f, "x");
      if (pnh.getParam("config", c)) {}
      pub_ = nh.advertise<skin3d::LandmarkArray>("stereo/landmarks", q, changed, changed);
      sub_ = nh.subscribe<sensor_msgs::Imu>("imu/data", 10, [this](const sensor_msgs::Imu::ConstPtr& m) { f(*m); });
      srv_ = pnh.advertiseService<A, B>("save_results", cb);
      sync_->subscribe(*nh_, "image_raw", queue_size_, approximate_, cb);
    '''
    assert code_params([code]) == {"queue_size", "frame", "config"}, code_params([code])
    topics, services = code_topics([code])
    assert topics == {"stereo/landmarks", "imu/data", "stereo/left/image_raw", "stereo/right/image_raw",
                      "stereo/left/camera_info", "stereo/right/camera_info"}, topics
    assert services == {"save_results"}, services
    doc = """## skin3d/x

### Subscribed topics

- `imu/data` (sensor_msgs/Imu, like `a/b` here)

### Published topics

- `stereo/landmarks`, `stereo/points` (things)
- TF `~world_frame` -> `~camera_frame`

### Services

- `~save_results` (skin3d/SaveResults)

### Parameters

| name | type | default | description |
|---|---|---|---|
| `~queue_size` | int | 5 | q |
| `~frame` | string | x | f |

## skin3d/y
"""
    d = doc_sections(doc)["x"]
    assert d["topics"] == {"imu/data", "stereo/landmarks", "stereo/points"}, d
    assert d["params"] == {"queue_size", "frame"}, d
    assert d["services"] == {"save_results"}, d
    return ""


def main():
    ap = argparse.ArgumentParser(usage=__doc__.replace("%", "%%"))
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    ap.add_argument("--xunit")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    results = []
    if a.self_test:
        try:
            results.append(("self_test", self_test()))
        except AssertionError as e:
            results.append(("self_test", "the readers are wrong: %s" % e))
    results += check(os.path.abspath(a.root))
    for name, msg in results:
        print("nodes_doc: %s: %s" % (name, "FAIL: " + msg if msg else "ok"))
    if a.xunit:
        write_xunit(a.xunit, "nodes_doc", results)
    return 1 if any(m for _, m in results) else 0


if __name__ == "__main__":
    sys.exit(main())
