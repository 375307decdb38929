// SPDX-License-Identifier: BSD-3-Clause
// The ROS layer's message conversions (skin3d/ros/conversions.h) that make_dataset writes and the nodelets and
// process_bag read back: camera_info and mono8 images, each against values set here by hand.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <stdexcept>

#include "skin3d/ros/conversions.h"

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

TEST(Conversions, Mono8MessageRefusesOtherImageTypes) {
  EXPECT_THROW(ros_conv::toMono8Msg(cv::Mat(4, 4, CV_8UC3), "f", ros::Time(1, 0)), std::invalid_argument);
  EXPECT_THROW(ros_conv::toMono8Msg(cv::Mat(4, 4, CV_16UC1), "f", ros::Time(1, 0)), std::invalid_argument);
}
