#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Ends a lossless replay when the chain has processed the whole bag.

usage: replay_done.py --bag FILE.bag [--frames-topic TOPIC] [--done-topic TOPIC] [--idle S] [--timeout S]
                      [--save SERVICE ...] [--save-timeout S]

The replay launch files start it as their required node: rosbag play may finish long before the nodes have worked
through their queues, and ending the launch with the player would lose the frames still queued. This node counts
the messages on --done-topic (default slam/odometry: one per frame the SLAM processed) and exits, which ends the
launch and makes the nodes write their results, when
- as many have come as the bag holds frames (messages on --frames-topic; default: stereo/left/image_raw when the
  bag has it, else stereo/landmarks; found at the root or under one namespace, as process_bag finds them), or
- none has come for --idle seconds (wall time, default 20) after the first one (frames were dropped), or
- --timeout seconds (wall time, default 0: none) have passed (the only way out when no frame can be processed).
The replay launch passes its idle:= and timeout:= arguments.
Before it exits it calls each --save service (skin3d/SaveResults with an empty directory: the node's ~results) and
waits for its answer (up to --save-timeout s, default 600): the results are written while the node runs, not in
its shutdown, which roslaunch cuts short after 15 s (a loaded machine, a long sweep); the node then has nothing
left to write when it stops. A service that is not there or fails is reported, and the node's own shutdown writes.
It says which on stdout. Exit status 0, or 2 on a bad command line or an unreadable bag.
"""
import argparse
import sys
import threading
import time


def frames_in_bag(path, topic):
    import rosbag
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info().topics
    names = list(info.keys())
    wanted = [topic] if topic else ["stereo/left/image_raw", "stereo/left/image_raw/compressed", "stereo/landmarks"]
    for w in wanted:
        for n in names:
            if n.lstrip("/") == w or n.endswith("/" + w):
                return info[n].message_count, n
    raise ValueError("%s has none of the topics %s (its topics: %s)" % (path, ", ".join(wanted), ", ".join(sorted(names))))


def main():
    ap = argparse.ArgumentParser(usage=__doc__.replace("%", "%%"))
    ap.add_argument("--bag", required=True)
    ap.add_argument("--frames-topic", default="")
    ap.add_argument("--done-topic", default="slam/odometry")
    ap.add_argument("--idle", type=float, default=20.0)
    ap.add_argument("--timeout", type=float, default=0.0)
    ap.add_argument("--save", action="append", default=[])
    ap.add_argument("--save-timeout", type=float, default=600.0)
    args, _ = ap.parse_known_args(sys.argv[1:])  # roslaunch adds __name:= and __log:=
    try:
        expected, topic = frames_in_bag(args.bag, args.frames_topic)
    except Exception as e:  # noqa: BLE001 - any unreadable bag is a command-line problem here
        print("replay_done: %s" % e, file=sys.stderr)
        return 2
    import rospy
    from rospy import AnyMsg
    rospy.init_node("replay_done", disable_signals=False)
    lock = threading.Lock()
    state = {"count": 0, "last": None}

    def on_done(_msg):
        with lock:
            state["count"] += 1
            state["last"] = time.monotonic()

    rospy.Subscriber(args.done_topic, AnyMsg, on_done, queue_size=100000)
    start = time.monotonic()
    why = ""
    while not rospy.is_shutdown():
        with lock:
            count, last = state["count"], state["last"]
        now = time.monotonic()
        if count >= expected:
            why = "all %d frames of %s processed" % (expected, topic)
        elif last is not None and now - last > args.idle:
            why = "%d of %d frames processed, none in the last %.0f s (the others were dropped)" % (count, expected, args.idle)
        elif args.timeout > 0 and now - start > args.timeout:
            why = "%d of %d frames processed when the --timeout of %.0f s passed" % (count, expected, args.timeout)
        if why:
            break
        time.sleep(0.1)
    print("replay_done: %s" % (why or "interrupted"))
    if why:
        for service in args.save:
            print("replay_done: %s" % save(service, args.save_timeout))
    return 0


def save(service, timeout):
    """Calls a skin3d/SaveResults service with an empty directory (the node's ~results); says what happened."""
    import rospy
    try:
        from skin3d.srv import SaveResults
    except ImportError as e:
        return "%s not called (%s): the node writes its results when it stops" % (service, e)
    try:
        rospy.wait_for_service(service, timeout=min(timeout, 10.0))
        t0 = time.monotonic()
        # a service call has no timeout of its own: it runs on a thread, and is given up after `timeout`
        result = {}

        def call():
            try:
                result["r"] = rospy.ServiceProxy(service, SaveResults)(directory="")
            except Exception as e:  # noqa: BLE001 - reported below
                result["e"] = e
        t = threading.Thread(target=call, daemon=True)
        t.start()
        t.join(timeout)
        if t.is_alive():
            return "%s: no answer within %.0f s: the node writes its results when it stops" % (service, timeout)
        if "e" in result:
            raise result["e"]
        r = result["r"]
        return "%s (%.1f s): %s%s" % (service, time.monotonic() - t0, "" if r.success else "FAILED: ", r.message)
    except Exception as e:  # noqa: BLE001 - any failure leaves the node's own shutdown to write
        return "%s failed (%s): the node writes its results when it stops" % (service, e)


if __name__ == "__main__":
    sys.exit(main())
