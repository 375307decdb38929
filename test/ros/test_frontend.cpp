// SPDX-License-Identifier: BSD-3-Clause
// rostest of the front-end nodelet (skin3d/stereo_front_end, with its defaults): a good synthetic frame gives
// landmarks at the depth the geometry says; each kind of bad input is dropped (or, for images without features,
// gives a frame without landmarks: the SLAM's prediction step) and the nodelet still answers the next good frame;
// the capture nodelet reads an image sequence with its calibration files.
#include <gtest/gtest.h>
#include <nodelet/NodeletList.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <skin3d/LandmarkArray.h>
#include <skin3d/StereoMatchArray.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <random>

namespace {

const double kF = 500.0, kB = 0.1, kShift = 20.0;  // f px, baseline m, disparity px: Z = f B / d = 2.5 m

struct Frame {
  sensor_msgs::Image left, right;
  sensor_msgs::CameraInfo left_info, right_info;
};

sensor_msgs::Image toMsg(const cv::Mat& img, const std::string& frame) {
  sensor_msgs::Image m;
  m.header.frame_id = frame;
  m.width = img.cols;
  m.height = img.rows;
  m.encoding = "mono8";
  m.step = img.cols;
  m.data.assign(img.datastart, img.dataend);
  return m;
}

sensor_msgs::CameraInfo info(int w, int h, const std::string& frame, double tx) {
  sensor_msgs::CameraInfo c;
  c.header.frame_id = frame;
  c.width = w;
  c.height = h;
  c.distortion_model = "plumb_bob";
  c.D = {0, 0, 0, 0, 0};
  c.K = {kF, 0, (w - 1) / 2.0, 0, kF, (h - 1) / 2.0, 0, 0, 1};
  c.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  c.P = {kF, 0, (w - 1) / 2.0, tx, 0, kF, (h - 1) / 2.0, 0, 0, 0, 1, 0};
  return c;
}

// A textured fronto-parallel scene: the right view is the left one shifted by kShift pixels.
Frame goodFrame(int w = 640, int h = 480) {
  static cv::Mat texture;
  if (texture.empty()) {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(0.f, 255.f);
    cv::Mat noise(h, w + 64, CV_32F);
    for (int r = 0; r < noise.rows; ++r)
      for (int c = 0; c < noise.cols; ++c) noise.at<float>(r, c) = u(rng);
    cv::GaussianBlur(noise, noise, cv::Size(0, 0), 2.0);
    cv::normalize(noise, noise, 0, 255, cv::NORM_MINMAX);
    noise.convertTo(texture, CV_8U);
  }
  Frame f;
  // Texture column c is at u = c in the left image and at u = c - kShift in the right one: disparity kShift.
  f.left = toMsg(texture(cv::Rect(0, 0, w, h)).clone(), "stereo_left_optical_frame");
  f.right = toMsg(texture(cv::Rect(static_cast<int>(kShift), 0, w, h)).clone(), "stereo_right_optical_frame");
  f.left_info = info(w, h, "stereo_left_optical_frame", 0.0);
  f.right_info = info(w, h, "stereo_right_optical_frame", -kF * kB);
  return f;
}

class FrontEnd : public ::testing::Test {
 protected:
  void SetUp() override {
    pl_ = nh_.advertise<sensor_msgs::Image>("stereo/left/image_raw", 5);
    pr_ = nh_.advertise<sensor_msgs::Image>("stereo/right/image_raw", 5);
    pli_ = nh_.advertise<sensor_msgs::CameraInfo>("stereo/left/camera_info", 5);
    pri_ = nh_.advertise<sensor_msgs::CameraInfo>("stereo/right/camera_info", 5);
    sub_ = nh_.subscribe("stereo/landmarks", 10, &FrontEnd::onLandmarks, this);
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
    while ((sub_.getNumPublishers() == 0 || pl_.getNumSubscribers() == 0 || pli_.getNumSubscribers() == 0) &&
           ros::WallTime::now() < deadline) {
      ros::spinOnce();
      ros::WallDuration(0.05).sleep();
    }
  }
  void onLandmarks(const skin3d::LandmarkArray::ConstPtr& m) { last_ = m, ++received_; }

  void send(Frame f, ros::Time stamp = ros::Time(0), ros::Time right_stamp = ros::Time(0)) {
    if (stamp.isZero()) stamp = next();
    if (right_stamp.isZero()) right_stamp = stamp;
    f.left.header.stamp = f.left_info.header.stamp = stamp;
    f.right.header.stamp = f.right_info.header.stamp = right_stamp;
    pli_.publish(f.left_info);
    pri_.publish(f.right_info);
    pl_.publish(f.left);
    pr_.publish(f.right);
  }
  ros::Time next() { return stamp_ += ros::Duration(0.1); }

  // Waits until `n` more landmark messages arrived (or the time-out).
  bool waitFor(int n, double seconds = 10.0) {
    const int target = received_ + n;
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
    while (received_ < target && ros::WallTime::now() < deadline) {
      ros::spinOnce();
      ros::WallDuration(0.02).sleep();
    }
    return received_ >= target;
  }
  void settle(double seconds = 0.7) {
    const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(seconds);
    while (ros::WallTime::now() < until) {
      ros::spinOnce();
      ros::WallDuration(0.02).sleep();
    }
  }

  ros::NodeHandle nh_;
  ros::Publisher pl_, pr_, pli_, pri_;
  ros::Subscriber sub_;
  skin3d::LandmarkArray::ConstPtr last_;
  int received_ = 0;
  ros::Time stamp_ = ros::Time(100.0);
};

void expectGoodLandmarks(const skin3d::LandmarkArray& m) {
  EXPECT_EQ(m.header.frame_id, "stereo_left_optical_frame");
  ASSERT_GE(m.landmarks.size(), 50u);
  std::vector<double> z;
  for (const auto& l : m.landmarks) {
    z.push_back(l.position.z);
    EXPECT_GT(l.covariance[8], 0.0);
    EXPECT_EQ(l.descriptor.size(), m.landmarks.front().descriptor.size());
    EXPECT_FALSE(l.descriptor.empty());
  }
  std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
  EXPECT_NEAR(z[z.size() / 2], kF * kB / kShift, 0.02 * kF * kB / kShift);
}

}  // namespace

TEST_F(FrontEnd, GoodFrameGivesLandmarksAtTheGeometricDepth) {
  send(goodFrame());
  ASSERT_TRUE(waitFor(1)) << "no stereo/landmarks for a good frame";
  expectGoodLandmarks(*last_);
}

TEST_F(FrontEnd, BadInputIsDroppedAndTheChainKeepsWorking) {
  struct Case {
    const char* name;
    std::function<void(Frame&)> spoil;
  };
  const std::vector<Case> cases = {
      {"mismatched left/right sizes", [](Frame& f) { f = goodFrame(); Frame s = goodFrame(320, 240); f.right = s.right; f.right_info = s.right_info; }},
      {"unsupported encoding", [](Frame& f) { f.left.encoding = "yuv422"; }},
      {"uncalibrated camera_info", [](Frame& f) { f.left_info.K[0] = 0.0; }},
      {"image/camera_info frame_id mismatch", [](Frame& f) { f.left.header.frame_id = "elsewhere"; }},
      {"same frame_id left and right", [](Frame& f) { f.right.header.frame_id = f.left.header.frame_id; f.right_info.header.frame_id = f.left.header.frame_id; }},
      {"empty image", [](Frame& f) { f.left.data.clear(); f.left.width = f.left.height = 0; }},
      {"black images", [](Frame& f) { std::fill(f.left.data.begin(), f.left.data.end(), 0); std::fill(f.right.data.begin(), f.right.data.end(), 0); }},
      {"textureless images (no features)", [](Frame& f) { std::fill(f.left.data.begin(), f.left.data.end(), 128); std::fill(f.right.data.begin(), f.right.data.end(), 128); }},
  };
  for (const auto& c : cases) {
    Frame f = goodFrame();
    c.spoil(f);
    const int before = received_;
    send(f);
    settle();
    EXPECT_TRUE(received_ == before || (last_ && last_->landmarks.empty())) << c.name << ": a bad frame produced landmarks";
    send(goodFrame());
    ASSERT_TRUE(waitFor(1)) << "after '" << c.name << "' the chain no longer answers a good frame";
    expectGoodLandmarks(*last_);
  }
  // Left and right stamps that differ: never paired (exact sync), no output, and the chain goes on.
  const int before = received_;
  const ros::Time t = next();
  send(goodFrame(), t, t + ros::Duration(0.033));
  settle();
  EXPECT_EQ(received_, before);
  send(goodFrame());
  ASSERT_TRUE(waitFor(1)) << "after a stamp mismatch the chain no longer answers";
  // The manager is alive with every nodelet.
  nodelet::NodeletList list;
  ASSERT_TRUE(ros::service::call("manager/list", list));
  EXPECT_GE(list.response.nodelets.size(), 3u);
}

TEST(StereoCapture, ImageSequenceWithCalibrationFiles) {
  ros::NodeHandle nh("capture");
  sensor_msgs::Image::ConstPtr left, right;
  sensor_msgs::CameraInfo::ConstPtr info;
  auto sl = nh.subscribe<sensor_msgs::Image>("stereo/left/image_raw", 5, [&](const sensor_msgs::Image::ConstPtr& m) { left = m; });
  auto sr = nh.subscribe<sensor_msgs::Image>("stereo/right/image_raw", 5, [&](const sensor_msgs::Image::ConstPtr& m) { right = m; });
  auto si = nh.subscribe<sensor_msgs::CameraInfo>("stereo/right/camera_info", 5,
                                                  [&](const sensor_msgs::CameraInfo::ConstPtr& m) { info = m; });
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
  while ((!left || !right || !info || left->header.stamp != right->header.stamp) && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  ASSERT_TRUE(left && right && info) << "no images from stereo_capture";
  EXPECT_EQ(left->header.stamp, right->header.stamp) << "one stamp for both images";
  EXPECT_EQ(left->width, 96u);
  EXPECT_EQ(left->header.frame_id, "stereo_left_optical_frame");
  EXPECT_EQ(right->header.frame_id, "stereo_right_optical_frame");
  EXPECT_DOUBLE_EQ(info->K[0], 100.0);  // from test/data/right.yaml
  EXPECT_DOUBLE_EQ(info->P[3], -10.0);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_frontend");
  return RUN_ALL_TESTS();
}
