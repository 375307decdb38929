// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file dense_cloud.h
 * @brief The organised point cloud of a dense stereo frame: a geometry type shared by the dense matcher
 * (stereo/dense_stereo.h, which makes it), the induration measurement and the results writers.
 */
#pragma once

#include <limits>
#include <opencv2/core.hpp>

namespace skin3d {
namespace geometry {

/** @brief Organised point cloud (one point per pixel of the left rectified image). */
struct DenseCloud {
  cv::Mat xyz;              //!< CV_32FC3, m, in the left camera's (unrectified) optical frame: R^T * X_rect; NaN unknown
  cv::Mat sigma;            //!< CV_32F, m, 1 sigma of the point along its viewing ray (from the disparity sigma)
  cv::Mat ray;              //!< CV_32FC3, unit viewing ray of every pixel (known or not), same frame as xyz
  /** The right camera's centre in the same frame (the left camera's is the origin); NaN if not known. */
  cv::Vec3d right_centre{std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN(),
                         std::numeric_limits<double>::quiet_NaN()};
};

}  // namespace geometry
}  // namespace skin3d
