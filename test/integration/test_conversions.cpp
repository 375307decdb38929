// SPDX-License-Identifier: BSD-3-Clause
// The ROS layer's message conversions (skin3d/ros/conversions.h) that make_dataset writes and the nodelets and
// process_bag read back: camera_info and mono8 images, each against values set here by hand; the input checks
// of every door (input_checks.h) and the stereo pairing's drops (stereo_pairs.h).
#include <gtest/gtest.h>

#include <functional>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "skin3d/ros/conversions.h"
#include "skin3d/ros/input_checks.h"
#include "skin3d/ros/stereo_pairs.h"

using namespace skin3d;

TEST(Conversions, CameraInfoRoundTripPadsTheDistortionToFive) {
  geometry::CameraInfo c;
  c.width = 640;
  c.height = 480;
  c.D = {-0.1, 0.02, 0.001, -0.002};  // k1 k2 p1 p2: no k3
  c.K << 800, 0, 320.5, 0, 810, 240.25, 0, 0, 1;
  c.R = Eigen::AngleAxisd(0.01, Eigen::Vector3d(0, 1, 0)).toRotationMatrix();
  c.P << 805, 0, 321, -40.25, 0, 805, 241, 0, 0, 0, 1, 0;
  const ros::Time t(1700000000, 250000000);
  const sensor_msgs::CameraInfo m = ros_conv::toMsg(c, "left_optical", t);
  EXPECT_EQ(m.header.frame_id, "left_optical");
  EXPECT_EQ(m.header.stamp, t);
  EXPECT_EQ(m.distortion_model, "plumb_bob");
  ASSERT_EQ(m.D.size(), 5u);
  EXPECT_EQ(m.D[4], 0.0);
  EXPECT_EQ(m.K[2], 320.5);   // row-major
  EXPECT_EQ(m.K[5], 240.25);
  EXPECT_EQ(m.P[3], -40.25);
  EXPECT_EQ(m.R[2], c.R(0, 2));
  EXPECT_TRUE(ros_conv::checkCameraInfo(m, "cam").empty()) << ros_conv::checkCameraInfo(m, "cam");

  const geometry::CameraInfo back = ros_conv::fromMsg(m);
  EXPECT_EQ(back.width, 640);
  EXPECT_EQ(back.height, 480);
  EXPECT_EQ(back.distortion_model, "plumb_bob");
  ASSERT_EQ(back.D.size(), 5u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(back.D[i], c.D[i]);
  EXPECT_EQ(back.K, c.K);
  EXPECT_EQ(back.R, c.R);
  EXPECT_EQ(back.P, c.P);
}

TEST(Conversions, Mono8ImageRoundTripKeepsEveryPixel) {
  // A region of interest: its rows are not contiguous in memory, so the copy must go row by row.
  cv::Mat big(7, 13, CV_8UC1);
  for (int r = 0; r < big.rows; ++r)
    for (int c = 0; c < big.cols; ++c) big.at<unsigned char>(r, c) = static_cast<unsigned char>(17 * r + 3 * c);
  const cv::Mat roi = big(cv::Rect(2, 1, 9, 5));
  const sensor_msgs::Image m = ros_conv::toMono8Msg(roi, "right_optical", ros::Time(5, 0));
  EXPECT_EQ(m.encoding, "mono8");
  EXPECT_EQ(m.width, 9u);
  EXPECT_EQ(m.height, 5u);
  EXPECT_EQ(m.step, 9u);
  ASSERT_EQ(m.data.size(), 45u);
  EXPECT_EQ(m.data[9 * 2 + 4], static_cast<unsigned char>(17 * 3 + 3 * 6));  // row 2, col 4 of the ROI
  EXPECT_TRUE(ros_conv::checkImage(m, nullptr, "img").empty()) << ros_conv::checkImage(m, nullptr, "img");
  const cv::Mat back = ros_conv::toMono8(m);
  EXPECT_EQ(cv::countNonZero(back != roi), 0);
}

TEST(Conversions, CompressedImagesDecodeAndUndecodableOnesAreNamed) {
  cv::Mat tex(48, 64, CV_8UC1);
  cv::randu(tex, 0, 255);
  cv::GaussianBlur(tex, tex, cv::Size(), 1.5);  // camera-like texture (JPEG is made for that, not white noise)
  const sensor_msgs::Image raw = ros_conv::toMono8Msg(tex, "left_optical", ros::Time(7, 0));
  // PNG: lossless, mono8 back, the header kept
  const sensor_msgs::CompressedImage png = ros_conv::toCompressed(raw, 0);
  EXPECT_NE(png.format.find("png"), std::string::npos) << png.format;
  const sensor_msgs::ImagePtr back = ros_conv::fromCompressed(png);
  EXPECT_EQ(back->encoding, "mono8");
  EXPECT_EQ(back->header.stamp, ros::Time(7, 0));
  EXPECT_EQ(back->header.frame_id, "left_optical");
  EXPECT_EQ(cv::countNonZero(ros_conv::toMono8(*back) != tex), 0);
  // JPEG: the same size, close (quality 95 on a smooth texture: under 2 grey levels on average)
  const sensor_msgs::CompressedImage jpg = ros_conv::toCompressed(raw, 95);
  EXPECT_LT(jpg.data.size(), png.data.size());
  const cv::Mat j = ros_conv::toMono8(*ros_conv::fromCompressed(jpg));
  ASSERT_EQ(j.size(), tex.size());
  cv::Mat diff;
  cv::absdiff(j, tex, diff);
  EXPECT_LT(cv::mean(diff)[0], 2.0);
  // a colour JPEG decodes to bgr8, which toMono8 converts
  cv::Mat colour;
  cv::cvtColor(tex, colour, cv::COLOR_GRAY2BGR);
  sensor_msgs::Image craw = raw;
  craw.encoding = "bgr8";
  craw.step = 3 * 64;
  craw.data.assign(colour.data, colour.data + colour.total() * 3);
  const sensor_msgs::ImagePtr cback = ros_conv::fromCompressed(ros_conv::toCompressed(craw, 95));
  EXPECT_EQ(cback->encoding, "bgr8");
  EXPECT_EQ(ros_conv::toMono8(*cback).size(), tex.size());
  // undecodable data and empty messages are named
  sensor_msgs::CompressedImage bad = jpg;
  bad.data.resize(20);
  std::fill(bad.data.begin(), bad.data.end(), 7);
  try {
    ros_conv::fromCompressed(bad);
    ADD_FAILURE() << "garbage decoded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cannot decode"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("20 bytes"), std::string::npos) << e.what();
  }
  bad.data.clear();
  EXPECT_THROW(ros_conv::fromCompressed(bad), std::invalid_argument);
  EXPECT_THROW(ros_conv::toCompressed(raw, 101), std::invalid_argument);
}

TEST(Conversions, Mono8MessageRefusesOtherImageTypes) {
  EXPECT_THROW(ros_conv::toMono8Msg(cv::Mat(4, 4, CV_8UC3), "f", ros::Time(1, 0)), std::invalid_argument);
  EXPECT_THROW(ros_conv::toMono8Msg(cv::Mat(4, 4, CV_16UC1), "f", ros::Time(1, 0)), std::invalid_argument);
}

// ------------------------------------------------------------------ input checks (skin3d/ros/input_checks.h)

namespace {
sensor_msgs::CameraInfo goodInfo() {
  geometry::CameraInfo c;
  c.width = 64;
  c.height = 48;
  c.D = {-0.1, 0.02, 0.001, -0.002, 0.0};
  c.K << 80, 0, 32, 0, 80, 24, 0, 0, 1;
  c.R = Eigen::AngleAxisd(0.01, Eigen::Vector3d(0, 1, 0)).toRotationMatrix();
  c.P << 80, 0, 32, -8, 0, 80, 24, 0, 0, 0, 1, 0;
  return ros_conv::toMsg(c, "left_optical", ros::Time(10, 0));
}

sensor_msgs::Imu goodImu() {
  sensor_msgs::Imu m;
  m.header.stamp = ros::Time(10, 0);
  m.angular_velocity.x = 0.01;
  m.angular_velocity_covariance[0] = m.angular_velocity_covariance[4] = m.angular_velocity_covariance[8] = 1e-6;
  m.orientation_covariance[0] = -1;
  return m;
}

sensor_msgs::ImagePtr monoImage(int w, int h, const ros::Time& t, const std::string& encoding = "mono8") {
  cv::Mat img(h, w, CV_8UC1);
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) img.at<unsigned char>(r, c) = static_cast<unsigned char>(r * 5 + c);
  sensor_msgs::ImagePtr m(new sensor_msgs::Image(ros_conv::toMono8Msg(img, "left_optical", t)));
  m->encoding = encoding;
  return m;
}
}  // namespace

TEST(InputChecks, CameraInfoNamesEveryNonFiniteEntryByMatrixAndIndex) {
  EXPECT_FALSE(ros_conv::checkCameraInfo(goodInfo())) << ros_conv::checkCameraInfo(goodInfo()).text();
  sensor_msgs::CameraInfo m = goodInfo();
  m.K[2] = std::numeric_limits<double>::quiet_NaN();
  m.D[1] = std::numeric_limits<double>::infinity();
  m.R[4] = std::numeric_limits<double>::quiet_NaN();
  m.P[0] = std::numeric_limits<double>::quiet_NaN();
  const auto f = ros_conv::checkCameraInfo(m);
  EXPECT_EQ(f.fault, "non-finite camera_info entries");
  for (const char* e : {"K[2] = nan", "D[1] = inf", "R[4] = nan", "P[0] = nan"})
    EXPECT_NE(f.detail.find(e), std::string::npos) << e << " in " << f.detail;
  EXPECT_EQ(f.text().find("is 0"), std::string::npos) << "a NaN is not a zero: " << f.text();
  // The wrapper of the nodelets: topic first.
  EXPECT_EQ(ros_conv::checkCameraInfo(m, "stereo/left/camera_info").rfind("stereo/left/camera_info: non-finite", 0), 0u);
}

TEST(InputChecks, CameraInfoRefusesZeroFocalLengthsAndMatricesOfTheWrongShape) {
  auto faultOf = [](const std::function<void(sensor_msgs::CameraInfo*)>& edit) {
    sensor_msgs::CameraInfo m = goodInfo();
    edit(&m);
    return ros_conv::checkCameraInfo(m).fault;
  };
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->K[0] = m->K[4] = 0; }), "uncalibrated camera_info");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->K[4] = -80; }), "camera_info focal length not positive");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->K[8] = 0; }), "camera_info K is not an intrinsic matrix");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->P[0] = m->P[5] = 0; }), "camera_info has no projection matrix");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->P[5] = 0; }), "camera_info projection focal length not positive");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->P[10] = 0; }), "camera_info P is not a projection matrix");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->R.fill(0.0); }), "camera_info R is not a rotation");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->R[0] = -1; }), "camera_info R is not a rotation");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->width = 0; }), "camera_info has no image size");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->D.resize(3); }), "camera_info D does not fit its distortion_model");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->distortion_model = "equidistant"; }), "unsupported distortion_model");
  EXPECT_EQ(faultOf([](sensor_msgs::CameraInfo* m) { m->D.clear(); }), "");  // plumb_bob without D: no distortion
}

TEST(InputChecks, ImuSamplesNeedFiniteRatesAndAPositiveDefiniteOrUnknownCovariance) {
  EXPECT_FALSE(ros_conv::checkImu(goodImu()));
  sensor_msgs::Imu m = goodImu();
  m.angular_velocity.y = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ros_conv::checkImu(m).fault, "non-finite angular velocity");
  EXPECT_EQ(ros_conv::checkImu(m).detail, "y = nan");
  m = goodImu();
  m.angular_velocity_covariance[4] = std::numeric_limits<double>::infinity();
  EXPECT_EQ(ros_conv::checkImu(m).fault, "non-finite angular velocity covariance");
  m = goodImu();
  m.angular_velocity_covariance[8] = 0;  // singular
  EXPECT_EQ(ros_conv::checkImu(m).fault, "angular velocity covariance not positive definite");
  m.angular_velocity_covariance[8] = -1e-6;
  EXPECT_EQ(ros_conv::checkImu(m).fault, "angular velocity covariance not positive definite");
  m = goodImu();
  m.angular_velocity_covariance[1] = 1e-7;  // not symmetric
  EXPECT_EQ(ros_conv::checkImu(m).fault, "angular velocity covariance not symmetric");
  // Unknown covariance: -1 in [0] (REP 145) or all zero; the SLAM then uses its gyro_noise.
  m = goodImu();
  m.angular_velocity_covariance.fill(0.0);
  EXPECT_FALSE(ros_conv::checkImu(m));
  m.angular_velocity_covariance[0] = -1;
  EXPECT_FALSE(ros_conv::checkImu(m));
  EXPECT_TRUE(ros_conv::gyroCovariance(m).isZero(0.0));
  // Orientation and acceleration are not read, so not checked.
  m = goodImu();
  m.orientation.x = std::numeric_limits<double>::quiet_NaN();
  m.linear_acceleration.z = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(ros_conv::checkImu(m));
}

TEST(InputChecks, Mono8And8UC1AreAcceptedAndConvertedWithoutCvBridge) {
  const auto m = monoImage(9, 5, ros::Time(1, 0), "8UC1");
  EXPECT_FALSE(ros_conv::checkImage(*m)) << ros_conv::checkImage(*m).text();
  const cv::Mat a = ros_conv::toMono8(*m);
  m->encoding = "mono8";
  const cv::Mat b = ros_conv::toMono8(*m);
  ASSERT_EQ(a.size(), cv::Size(9, 5));
  EXPECT_EQ(cv::countNonZero(a != b), 0);
  // 16UC1 as mono16, scaled by 1/256, either byte order.
  sensor_msgs::Image w;
  w.width = 2;
  w.height = 1;
  w.step = 4;
  w.encoding = "16UC1";
  w.is_bigendian = 0;
  w.data = {0x00, 0x12, 0x00, 0xff};  // little-endian 0x1200, 0xff00
  EXPECT_FALSE(ros_conv::checkImage(w));
  cv::Mat g = ros_conv::toMono8(w);
  EXPECT_EQ(g.at<unsigned char>(0, 0), 0x12);
  EXPECT_EQ(g.at<unsigned char>(0, 1), 0xff);
  w.is_bigendian = 1;
  w.data = {0x12, 0x00, 0xff, 0x00};
  g = ros_conv::toMono8(w);
  EXPECT_EQ(g.at<unsigned char>(0, 0), 0x12);
  EXPECT_EQ(g.at<unsigned char>(0, 1), 0xff);
}

TEST(InputChecks, ImagesNameTheirFault) {
  auto m = monoImage(64, 48, ros::Time(1, 0));
  const sensor_msgs::CameraInfo info = goodInfo();
  EXPECT_FALSE(ros_conv::checkImage(*m, &info));
  m->encoding = "32FC1";
  EXPECT_EQ(ros_conv::checkImage(*m).fault, "unsupported encoding");
  EXPECT_NE(ros_conv::checkImage(*m).detail.find("'32FC1'"), std::string::npos);
  m = monoImage(32, 48, ros::Time(1, 0));
  EXPECT_EQ(ros_conv::checkImage(*m, &info).fault, "image size differs from its camera_info's");
  m->data.resize(10);
  EXPECT_EQ(ros_conv::checkImage(*m).fault, "image data shorter than step x height");
  m->step = 3;
  EXPECT_EQ(ros_conv::checkImage(*m).fault, "image step smaller than a row");
  m->data.clear();
  EXPECT_EQ(ros_conv::checkImage(*m).fault, "empty image");
}

TEST(InputChecks, StampOrderRefusesZeroDuplicateAndBackwardsStamps) {
  ros_conv::StampOrder o;
  EXPECT_EQ(o.admit(ros::Time()).fault, "zero stamp");
  EXPECT_FALSE(o.admit(ros::Time(10, 0)));
  EXPECT_EQ(o.admit(ros::Time(10, 0)).fault, "duplicate stamp");
  EXPECT_EQ(o.admit(ros::Time(9, 500000000)).fault, "stamp goes backwards");
  EXPECT_NE(o.admit(ros::Time(9, 500000000)).detail.find("0.500000000 s before"), std::string::npos);
  EXPECT_FALSE(o.admit(ros::Time(10, 1))) << "a bad stamp is not remembered";
}

TEST(StereoPairs, UnpairedImagesAndBadMessagesAreHandedToTheDropHandler) {
  ros_io::StereoPairs pairs;
  std::vector<std::string> drops;
  pairs.setDropHandler([&](const std::string& topic, double t, const std::string& fault, const std::string&) {
    drops.push_back(topic + "@" + std::to_string(static_cast<int>(t)) + ": " + fault);
  });
  sensor_msgs::CameraInfo bad = goodInfo();
  bad.P[3] = std::numeric_limits<double>::quiet_NaN();
  pairs.addCameraInfo(true, bad);
  pairs.addCameraInfo(true, goodInfo());
  pairs.addCameraInfo(false, goodInfo());
  ASSERT_TRUE(pairs.calibrated());
  pairs.addImage(true, monoImage(64, 48, ros::Time(1, 0)));
  pairs.addImage(false, monoImage(64, 48, ros::Time(1, 0), "8UC1"));
  pairs.addImage(true, monoImage(64, 48, ros::Time(2, 0)));  // its right image is missing
  pairs.addImage(true, monoImage(64, 48, ros::Time(3, 0)));
  pairs.addImage(false, monoImage(64, 48, ros::Time(3, 0)));
  pairs.addImage(true, monoImage(64, 48, ros::Time(3, 0)));  // duplicate
  pairs.addImage(true, monoImage(64, 48, ros::Time(4, 0)));
  pairs.addImage(false, monoImage(32, 48, ros::Time(4, 0)));  // wrong size: both dropped at pairing
  pairs.addImage(true, monoImage(64, 48, ros::Time(5, 0)));  // last left without a right one: dropped at flush
  sensor_msgs::Image::ConstPtr l, r;
  std::vector<int> stamps;
  while (pairs.next(&l, &r)) {
    EXPECT_EQ(l->header.stamp, r->header.stamp);
    EXPECT_NO_THROW(pairs.rectifyRight(*r));
    stamps.push_back(static_cast<int>(l->header.stamp.sec));
  }
  pairs.flush();
  EXPECT_EQ(stamps, (std::vector<int>{1, 3}));
  EXPECT_EQ(pairs.unpairedLeft(), 2);
  EXPECT_EQ(pairs.unpairedRight(), 0);
  const std::vector<std::string> want = {
      "stereo/left/camera_info@10: non-finite camera_info entries",
      "stereo/left/image_raw@3: duplicate stamp",
      "stereo/left/image_raw@2: no right image with this stamp",
      "stereo/left/image_raw@4: no usable right image with this stamp",
      "stereo/right/image_raw@4: image size differs from its camera_info's",
      "stereo/left/image_raw@5: no right image with this stamp"};
  EXPECT_EQ(drops, want);
  EXPECT_EQ(pairs.dropped(), 6);
}
