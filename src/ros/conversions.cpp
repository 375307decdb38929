// SPDX-License-Identifier: BSD-3-Clause
// skin3d_ros: ROS message <-> core struct conversions (see include/skin3d/ros/conversions.h).
#include "skin3d/ros/conversions.h"

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>
#include <opencv2/imgcodecs.hpp>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace skin3d {
namespace ros_conv {

geometry_msgs::Pose toPoseMsg(const Eigen::Vector3d& p, const Eigen::Quaterniond& q) {
  geometry_msgs::Pose m;
  m.position.x = p.x();
  m.position.y = p.y();
  m.position.z = p.z();
  m.orientation.w = q.w();
  m.orientation.x = q.x();
  m.orientation.y = q.y();
  m.orientation.z = q.z();
  return m;
}

geometry::CameraInfo fromMsg(const sensor_msgs::CameraInfo& m) {
  geometry::CameraInfo c;
  c.width = static_cast<int>(m.width);
  c.height = static_cast<int>(m.height);
  c.distortion_model = m.distortion_model;
  c.D = m.D;
  for (int i = 0; i < 9; ++i) c.K(i / 3, i % 3) = m.K[i];
  for (int i = 0; i < 9; ++i) c.R(i / 3, i % 3) = m.R[i];
  for (int i = 0; i < 12; ++i) c.P(i / 4, i % 4) = m.P[i];
  return c;
}

sensor_msgs::CameraInfo toMsg(const geometry::CameraInfo& c, const std::string& frame, const ros::Time& t) {
  sensor_msgs::CameraInfo m;
  m.header.frame_id = frame;
  m.header.stamp = t;
  m.width = c.width;
  m.height = c.height;
  m.distortion_model = "plumb_bob";
  m.D = c.D;
  m.D.resize(5, 0.0);
  for (int i = 0; i < 9; ++i) m.K[i] = c.K(i / 3, i % 3);
  for (int i = 0; i < 9; ++i) m.R[i] = c.R(i / 3, i % 3);
  for (int i = 0; i < 12; ++i) m.P[i] = c.P(i / 4, i % 4);
  return m;
}

std::vector<slam::Measurement> fromMsg(const skin3d::LandmarkArray& a) {
  std::vector<slam::Measurement> out;
  out.reserve(a.landmarks.size());
  for (const auto& l : a.landmarks) {
    slam::Measurement m;
    m.z = Eigen::Vector3d(l.position.x, l.position.y, l.position.z);
    for (int i = 0; i < 9; ++i) m.C(i / 3, i % 3) = l.covariance[i];
    m.descriptor = l.descriptor;
    m.strength = l.strength;
    out.push_back(std::move(m));
  }
  return out;
}

skin3d::Landmark toLandmarkMsg(const Eigen::Vector3d& position, const Eigen::Matrix3d& covariance,
                               const std::vector<float>& descriptor, float strength,
                               const Eigen::Vector2d& uv_left, const Eigen::Vector2d& uv_right) {
  skin3d::Landmark m;
  m.position.x = position.x();
  m.position.y = position.y();
  m.position.z = position.z();
  for (int i = 0; i < 9; ++i) m.covariance[i] = covariance(i / 3, i % 3);
  m.descriptor = descriptor;
  m.strength = strength;
  m.u_left = uv_left.x();
  m.v_left = uv_left.y();
  m.u_right = uv_right.x();
  m.v_right = uv_right.y();
  return m;
}

std::string checkCameraInfo(const sensor_msgs::CameraInfo& m, const std::string& topic) {
  const InputFault f = checkCameraInfo(m);
  return f ? topic + ": " + f.text() : std::string();
}

std::string checkImage(const sensor_msgs::Image& img, const sensor_msgs::CameraInfo* info, const std::string& topic) {
  const InputFault f = checkImage(img, info);
  return f ? topic + ": " + f.text() : std::string();
}

cv::Mat toMono8(const sensor_msgs::Image& img) {
  namespace enc = sensor_msgs::image_encodings;
  const bool mono8 = img.encoding == enc::MONO8 || img.encoding == enc::TYPE_8UC1;
  const bool mono16 = img.encoding == enc::MONO16 || img.encoding == enc::TYPE_16UC1;
  if (mono8 || mono16) {  // single channel: read directly (cv_bridge refuses 8UC1 -> mono8)
    if (const InputFault f = checkImage(img)) throw std::invalid_argument("toMono8: " + f.text());
    const cv::Mat view(static_cast<int>(img.height), static_cast<int>(img.width), mono8 ? CV_8UC1 : CV_16UC1,
                       const_cast<uint8_t*>(img.data.data()), img.step);
    if (mono8) return view.clone();
    cv::Mat m16 = view.clone(), m8;
    const bool host_big_endian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
    if (static_cast<bool>(img.is_bigendian) != host_big_endian)
      for (int r = 0; r < m16.rows; ++r)
        for (auto* p = m16.ptr<uint16_t>(r), *e = p + m16.cols; p != e; ++p) *p = static_cast<uint16_t>((*p >> 8) | (*p << 8));
    m16.convertTo(m8, CV_8U, 1.0 / 256.0);
    return m8;
  }
  return cv_bridge::toCvCopy(img, enc::MONO8)->image;
}

sensor_msgs::ImagePtr fromCompressed(const sensor_msgs::CompressedImage& m) {
  namespace enc = sensor_msgs::image_encodings;
  const std::string what = "compressed image (format '" + m.format + "', " + std::to_string(m.data.size()) + " bytes)";
  if (m.data.empty()) throw std::invalid_argument("empty " + what);
  cv::Mat im;
  try {
    im = cv::imdecode(cv::Mat(1, static_cast<int>(m.data.size()), CV_8U, const_cast<uint8_t*>(m.data.data())),
                      cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw std::invalid_argument("cannot decode the " + what + ": " + e.what());
  }
  if (im.empty()) throw std::invalid_argument("cannot decode the " + what + ": not a JPEG or PNG image OpenCV reads");
  std::string encoding;
  switch (im.type()) {
    case CV_8UC1: encoding = enc::MONO8; break;
    case CV_8UC3: encoding = enc::BGR8; break;
    case CV_8UC4: encoding = enc::BGRA8; break;
    case CV_16UC1: encoding = enc::MONO16; break;
    default: throw std::invalid_argument("the " + what + " decodes to an OpenCV type " + std::to_string(im.type()) +
                                         " skin3d does not read (8-bit grey or colour, 16-bit grey)");
  }
  cv_bridge::CvImage out(m.header, encoding, im);
  return out.toImageMsg();
}

sensor_msgs::CompressedImage toCompressed(const sensor_msgs::Image& img, int jpeg_quality) {
  if (jpeg_quality < 0 || jpeg_quality > 100) throw std::invalid_argument("toCompressed: JPEG quality must be 0 (PNG) ... 100");
  const cv::Mat im = cv_bridge::toCvCopy(img)->image;
  sensor_msgs::CompressedImage m;
  m.header = img.header;
  m.format = jpeg_quality > 0 ? img.encoding + "; jpeg compressed " + (im.channels() == 1 ? "mono8" : "bgr8")
                              : img.encoding + "; png compressed " + img.encoding;
  std::vector<uint8_t> buf;
  if (!cv::imencode(jpeg_quality > 0 ? ".jpg" : ".png", im, buf,
                    jpeg_quality > 0 ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, jpeg_quality} : std::vector<int>{}))
    throw std::runtime_error("toCompressed: OpenCV could not encode the image");
  m.data = std::move(buf);
  return m;
}

sensor_msgs::Image toMono8Msg(const cv::Mat& img, const std::string& frame, const ros::Time& t) {
  if (img.type() != CV_8UC1) throw std::invalid_argument("toMono8Msg: the image is not 8-bit single-channel");
  sensor_msgs::Image m;
  m.header.frame_id = frame;
  m.header.stamp = t;
  m.height = img.rows;
  m.width = img.cols;
  m.encoding = "mono8";
  m.is_bigendian = 0;
  m.step = img.cols;
  m.data.resize(static_cast<size_t>(img.rows) * img.cols);
  for (int r = 0; r < img.rows; ++r) std::memcpy(&m.data[static_cast<size_t>(r) * img.cols], img.ptr(r), img.cols);
  return m;
}

bool xmlRpcToText(XmlRpc::XmlRpcValue& v, std::string* text) {
  std::ostringstream out;
  out.precision(17);
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean: out << (static_cast<bool>(v) ? "true" : "false"); break;
    case XmlRpc::XmlRpcValue::TypeInt: out << static_cast<int>(v); break;
    case XmlRpc::XmlRpcValue::TypeDouble: out << static_cast<double>(v); break;
    case XmlRpc::XmlRpcValue::TypeString: out << static_cast<std::string>(v); break;
    case XmlRpc::XmlRpcValue::TypeArray:
      for (int i = 0; i < v.size(); ++i) {
        std::string item;
        if (v[i].getType() == XmlRpc::XmlRpcValue::TypeArray || !xmlRpcToText(v[i], &item)) return false;
        out << (i ? " " : "") << item;
      }
      break;
    default: return false;
  }
  *text = out.str();
  return true;
}

void loadOptionParams(const ros::NodeHandle& pnh, const std::vector<std::string>& keys,
                      const std::function<void(const std::string&, const std::string&)>& set,
                      const std::function<std::string(const std::string&)>& get, std::vector<std::string>* errors) {
  for (const std::string& key : keys) {
    XmlRpc::XmlRpcValue v;
    if (!pnh.getParam(key, v)) continue;
    std::string text;
    if (!xmlRpcToText(v, &text)) {
      errors->push_back("parameter ~" + key + " must be a value or a list of values; keeping " + get(key));
      continue;
    }
    try {
      set(key, text);
    } catch (const std::exception& e) {
      errors->push_back(std::string(e.what()) + "; keeping " + get(key));
    }
  }
}

induration::PipelineOptions loadPipelineOptions(const ros::NodeHandle& pnh, std::vector<std::string>* errors) {
  induration::PipelineOptions opt;
  std::string config;
  if (pnh.getParam("config", config) && !config.empty()) {
    try {
      induration::applyPipelineOptions(&opt, config);
    } catch (const std::exception& e) {
      errors->push_back(std::string("~config: ") + e.what());
    }
  }
  loadOptionParams(
      pnh, induration::pipelineOptionKeys(),
      [&](const std::string& k, const std::string& v) { induration::setPipelineOption(&opt, k, v); },
      [&](const std::string& k) { return induration::getPipelineOption(opt, k); }, errors);
  try {
    opt.validate();
  } catch (const std::exception& e) {
    errors->push_back(std::string(e.what()) + "; using the defaults of config/induration.yaml for every parameter");
    opt = induration::PipelineOptions();
  }
  return opt;
}

sensor_msgs::PointCloud2Ptr toCloudMsg(const stereo::DenseCloud& cloud, const cv::Mat& colour,
                                       const std_msgs::Header& header) {
  const sensor_msgs::PointCloud2Ptr pc(new sensor_msgs::PointCloud2);
  pc->header = header;
  sensor_msgs::PointCloud2Modifier mod(*pc);
  const auto F = sensor_msgs::PointField::FLOAT32;
  mod.setPointCloud2Fields(kDenseCloudFields, "x", 1, F, "y", 1, F, "z", 1, F, "rgb", 1, F, "sigma", 1, F, "ray_x", 1,
                           F, "ray_y", 1, F, "ray_z", 1, F);
  const int rows = cloud.xyz.rows, cols = cloud.xyz.cols;
  mod.resize(static_cast<size_t>(rows) * cols);
  pc->height = rows;
  pc->width = cols;
  pc->row_step = cols * pc->point_step;
  pc->is_dense = false;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const bool has_sigma = cloud.sigma.size() == cloud.xyz.size() && cloud.sigma.type() == CV_32F;
  const bool has_ray = cloud.ray.size() == cloud.xyz.size() && cloud.ray.type() == CV_32FC3;
  const bool has_colour = colour.size() == cloud.xyz.size() && colour.depth() == CV_8U &&
                          (colour.channels() == 1 || colour.channels() == 3);
  float p[kDenseCloudFields];
  uint8_t* out = pc->data.data();
  for (int v = 0; v < rows; ++v)
    for (int u = 0; u < cols; ++u, out += pc->point_step) {
      const cv::Vec3f& X = cloud.xyz.at<cv::Vec3f>(v, u);
      p[kX] = X[0], p[kY] = X[1], p[kZ] = X[2];
      uint8_t bgr[3] = {255, 255, 255};
      if (has_colour && colour.channels() == 1) bgr[0] = bgr[1] = bgr[2] = colour.at<uint8_t>(v, u);
      if (has_colour && colour.channels() == 3) {
        const cv::Vec3b& c = colour.at<cv::Vec3b>(v, u);
        bgr[0] = c[0], bgr[1] = c[1], bgr[2] = c[2];
      }
      const uint32_t rgb = (uint32_t(bgr[2]) << 16) | (uint32_t(bgr[1]) << 8) | uint32_t(bgr[0]);
      std::memcpy(&p[kRgb], &rgb, sizeof(float));
      p[kSigma] = has_sigma ? cloud.sigma.at<float>(v, u) : nan;
      const cv::Vec3f r = has_ray ? cloud.ray.at<cv::Vec3f>(v, u) : cv::Vec3f(nan, nan, nan);
      p[kRayX] = r[0], p[kRayY] = r[1], p[kRayZ] = r[2];
      std::memcpy(out, p, sizeof(p));
    }
  return pc;
}

std::string fromCloudMsg(const sensor_msgs::PointCloud2& pc, const std::string& topic,
                         stereo::DenseCloud* cloud, cv::Mat* colour) {
  auto field = [&pc](const std::string& name) -> const sensor_msgs::PointField* {
    for (const auto& f : pc.fields)
      if (f.name == name) return &f;
    return nullptr;
  };
  if (pc.height < 2 || pc.width < 2)
    return topic + ": the cloud is not organised (" + std::to_string(pc.width) + "x" + std::to_string(pc.height) +
           "); an image-shaped cloud from skin3d/dense_stereo is needed";
  for (const char* name : {"x", "y", "z"}) {
    const auto* f = field(name);
    if (!f) return topic + ": the cloud has no field '" + name + "'";
    if (f->datatype != sensor_msgs::PointField::FLOAT32 || f->count != 1 || f->offset + 4 > pc.point_step)
      return topic + ": field '" + name + "' is not one float32 inside the point";
  }
  if (pc.is_bigendian) return topic + ": big-endian clouds are not supported";
  if (pc.row_step != pc.width * pc.point_step || pc.data.size() != static_cast<size_t>(pc.row_step) * pc.height)
    return topic + ": data size " + std::to_string(pc.data.size()) + " does not match " + std::to_string(pc.height) +
           " rows of " + std::to_string(pc.width) + " points of " + std::to_string(pc.point_step) + " bytes";
  auto floatField = [&](const std::string& name) -> int {
    const auto* f = field(name);
    return f && f->datatype == sensor_msgs::PointField::FLOAT32 && f->count == 1 && f->offset + 4 <= pc.point_step
               ? static_cast<int>(f->offset)
               : -1;
  };
  const int ox = floatField("x"), oy = floatField("y"), oz = floatField("z"), os = floatField("sigma");
  const int orx = floatField("ray_x"), ory = floatField("ray_y"), orz = floatField("ray_z");
  const bool has_ray = orx >= 0 && ory >= 0 && orz >= 0;
  const auto* rgb = field("rgb");
  const int orgb = rgb && rgb->count == 1 && rgb->offset + 4 <= pc.point_step &&
                           (rgb->datatype == sensor_msgs::PointField::FLOAT32 ||
                            rgb->datatype == sensor_msgs::PointField::UINT32)
                       ? static_cast<int>(rgb->offset)
                       : -1;
  const int rows = static_cast<int>(pc.height), cols = static_cast<int>(pc.width);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cloud->xyz.create(rows, cols, CV_32FC3);
  cloud->sigma.create(rows, cols, CV_32F);
  cloud->ray.create(rows, cols, CV_32FC3);
  if (colour) {
    if (orgb >= 0)
      colour->create(rows, cols, CV_8UC3);
    else
      *colour = cv::Mat();
  }
  auto get = [](const uint8_t* p, int offset) {
    float f;
    std::memcpy(&f, p + offset, sizeof(float));
    return f;
  };
  const uint8_t* in = pc.data.data();
  for (int v = 0; v < rows; ++v)
    for (int u = 0; u < cols; ++u, in += pc.point_step) {
      const cv::Vec3f X(get(in, ox), get(in, oy), get(in, oz));
      const bool known = std::isfinite(X[0]) && std::isfinite(X[1]) && std::isfinite(X[2]);
      cloud->xyz.at<cv::Vec3f>(v, u) = known ? X : cv::Vec3f(nan, nan, nan);
      float s = os >= 0 ? get(in, os) : 0.0f;
      if (!std::isfinite(s)) s = known ? 0.0f : nan;
      cloud->sigma.at<float>(v, u) = known ? s : nan;
      if (has_ray) {
        cloud->ray.at<cv::Vec3f>(v, u) = cv::Vec3f(get(in, orx), get(in, ory), get(in, orz));
      } else {
        const float n = std::sqrt(X.dot(X));
        cloud->ray.at<cv::Vec3f>(v, u) = known && n > 0 ? X / n : cv::Vec3f(nan, nan, nan);
      }
      if (colour && orgb >= 0) {  // packed 0x00RRGGBB, little-endian: bytes b g r
        const uint8_t* c = in + orgb;
        colour->at<cv::Vec3b>(v, u) = cv::Vec3b(c[0], c[1], c[2]);
      }
    }
  return "";
}

skin3d::IndurationReport toReportMsg(const induration::IndurationResult& r, const std_msgs::Header& header) {
  skin3d::IndurationReport m;
  m.header = header;
  const Eigen::Vector4d plane = r.reference.plane();
  for (int i = 0; i < 4; ++i) m.reference_plane[i] = plane[i];
  m.reference_rms = r.reference.rms;
  for (const auto& p : r.plaques) {
    skin3d::Plaque q;
    q.id = static_cast<uint32_t>(p.id);
    q.centroid.x = p.centroid.x();
    q.centroid.y = p.centroid.y();
    q.centroid.z = p.centroid.z();
    q.area = p.area;
    q.top_height = p.top_height;
    q.top_height_sigma = p.top_height_sigma;
    q.mean_height = p.mean_height;
    q.max_height = p.max_height;
    q.std_height = p.std_height;
    q.pasi_class = static_cast<uint8_t>(p.pasi_class);
    m.plaques.push_back(q);
  }
  m.warnings = r.warnings;
  return m;
}

}  // namespace ros_conv
}  // namespace skin3d
