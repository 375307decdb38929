// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file frame_measurer.h
 * @brief The induration measurement of one stereo pair as one object: a raw pair and its calibration ->
 * rectification -> the working depth range (searched in the pair, or z_min / z_max) -> dense disparity with its sigma
 * -> the organised cloud ->
 * the healthy-skin reference and the plaques. Every door runs this class: the induration nodelet (live) and
 * `process_bag --induration` (offline), configured by one options table (induration::PipelineOptions, the keys of
 * config/induration.yaml); measurementResults() writes the results directory for both.
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "skin3d/geometry/camera.h"
#include "skin3d/induration/induration_config.h"
#include "skin3d/induration/induration_io.h"
#include "skin3d/stereo/dense_stereo.h"
#include "skin3d/stereo/front_end.h"

namespace skin3d {
namespace induration {

/** @brief One pair through the frame measurer. */
struct FrameMeasurement {
  FrameRecord record;                //!< stamp, result, valid_fraction (known disparity / matched region), seconds
  stereo::DisparityMap disparity;    //!< disparity and its sigma, px (NaN unknown)
  stereo::DenseCloud cloud;          //!< organised like the left rectified image, left optical frame
  cv::Mat left_rect;                 //!< the rectified left image (mono8)
  double seconds_rectify = 0, seconds_range = 0, seconds_match = 0, seconds_triangulate = 0, seconds_measure = 0;
  std::string range_note;            //!< why the depth range search found nothing (empty: it did, or it was set)
};

class FrameMeasurer {
 public:
  /** @throws std::invalid_argument for bad options (validate()). */
  explicit FrameMeasurer(const PipelineOptions& options);
  const PipelineOptions& options() const { return options_; }

  /** @brief A raw pair (mono8) with its calibration, stamped `stamp` (s).
   *  @throws std::invalid_argument for a pair that cannot be processed (sizes, calibration), naming why. */
  FrameMeasurement measure(const cv::Mat& left_raw, const cv::Mat& right_raw, const geometry::CameraInfo& left,
                           const geometry::CameraInfo& right, double stamp);
  /** @brief measure()'s first half: rectification, the depth range, dense matching and the cloud (not the
   *  induration measurement). Not thread-safe (it keeps the rectification); finish() may run on another thread. */
  FrameMeasurement match(const cv::Mat& left_raw, const cv::Mat& right_raw, const geometry::CameraInfo& left,
                         const geometry::CameraInfo& right, double stamp);
  /** @brief measure()'s second half on match()'s result: the reference, the plaques, the record. Thread-safe
   *  (reads only the options): a pipeline measures one pair while it matches the next. */
  void finish(FrameMeasurement* m) const;

 private:
  PipelineOptions options_;
  stereo::PairRectifier rectify_;
};

/**
 * @brief The results directory of a run (every door): induration.yaml (every frame and the repeatability over
 * frames), parameters.yaml (every key's value), and from the last frame height_map.png, surface.ply (every
 * `ply_step`-th pixel) and its maps (writeFrameMaps: disparity.tiff, disparity_sigma.tiff (px), left_rect.png,
 * unknown_reason.png, height_map.tiff (m)); a run that keeps every frame's maps has them in frames/NNNN/ too. `frames` keeps maps only where given (the last frame's are `last`'s). induration.yaml ends
 * with frames_dropped and dropped_input (what the door dropped before measuring, by fault).
 * @throws std::runtime_error naming the file that cannot be written.
 */
void writeMeasurementResults(const std::string& dir, const std::vector<FrameRecord>& frames,
                             const FrameMeasurement& last, const PipelineOptions& options,
                             const std::string& frame_id, const std::string& source,
                             const std::vector<std::string>& command_line, int frames_dropped = 0,
                             const std::string& dropped_input = "none", int ply_step = 2);

/**
 * @brief The maps of one frame into `dir` (created with its parents): height_map.png (picture), height_map.tiff (m,
 * NaN unknown), disparity.tiff and disparity_sigma.tiff (px), left_rect.png, unknown_reason.png.
 * @throws std::runtime_error naming the file that cannot be written.
 */
void writeFrameMaps(const std::string& dir, const FrameMeasurement& m);

/** @brief Where a run that keeps every frame's maps writes frame `index` (0-based): RESULTS/frames/0007. */
std::string frameMapsDirectory(const std::string& results, int index);

}  // namespace induration
}  // namespace skin3d
