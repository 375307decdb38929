// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file site_fusion.h
 * @brief The site scan: many stereo frames of one body site, each measured on its own (FrameMeasurer), fused into
 * one height field over the body's surface, and the plaques measured once on it.
 *
 * 1. **The body surface** is chosen from the first frame's healthy-skin reference: a quadric whose quadratic part has
 *    one eigenvalue near zero and two of one sign is a limb (an elliptic cylinder): the site is unrolled around its
 *    axis, (u along the axis, v = R theta around it, w = distance from the axis); anything else is a plane, (u, v) in
 *    it and w along its normal. `SiteSurface::model` says which ("cylinder" or "plane").
 * 2. **Registration** (`register_frames`): each frame after the first is aligned to the surface fused so far by
 *    point-to-plane Levenberg-Marquardt (Huber-weighted, every `register_stride`-th pixel, a step taken only when it
 *    lowers the cost), starting from the pose given with it; the residual of a point is n . (X - P), P the fused
 *    surface where the point falls and n its normal, weighted by the point's and the cell's sigma. It stops when no
 *    step lowers the cost or a step moves the samples by under a tenth of their residual scatter (at most
 *    `register_iterations`). A frame that overlaps the fused surface on less than `min_overlap` of its samples, or
 *    whose alignment moves it more than `max_correction`, is left out and named.
 * 3. **Fusion**: every sample within `max_incidence_deg` of the body normal in both cameras is splatted bilinearly
 *    into cells of `cell` m (0: the first frame's median pixel footprint on the skin: no finer than the data), with
 *    the weight cos^2(incidence) / sigma^2 (sigma the matcher's along the ray; a grazing view's lateral footprint
 *    and its sensitivity to slopes grow as 1 / cos): an inverse-variance mean of w per cell, its sigma, how many
 *    frames contributed and which contributed most. Seams: before a frame is fused, the mean of its samples and of
 *    the fused surface over 2 mm blocks where both exist; their RMS difference is the frame's `seam_rms`, the RMS the
 *    stated sigmas alone explain `seam_noise` (independent samples: the matcher's correlated noise makes the true
 *    floor higher), what is left beyond it `seam_excess`, and `seam_rigid`: the RMS of the plane that best fits the
 *    block differences (the part a pose error leaves, which the noise of thousands of blocks hardly disturbs).
 * 4. **The site measurement**: a smooth body model is fitted to the fused w (cylinder: a Fourier series in theta to
 *    the 4th harmonic, each term linear along the axis, plus u^2; plane: quadratic in u, v) with Tukey weights; the
 *    heights above it along its normal make an unrolled height map that measureInduration (induration.h) measures as
 *    one frame seen from straight above (its working band is the fused surface: `max_incidence_deg` was applied in
 *    the fusion). Plaques found there are mapped back to `world`, the body model fitted again without them, and
 *    the map measured once more. Areas and volumes are corrected from the unrolled map to the body (the surface
 *    element's stretch at the plaque). A raised region that no frame saw within 45 deg in both cameras is listed
 *    apart (`grazing`), not as a plaque. Per plaque: the views that measured it on their own (each frame's plaques
 *    nearer than the plaque's radius), the spread of their top heights, the best incidence any frame had on it.
 *
 * The class is ROS-free; `process_bag --site` and the site_fusion nodelet feed it.
 */
#pragma once

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "skin3d/geometry/dense_cloud.h"
#include "skin3d/induration/induration.h"

namespace skin3d {
namespace site {

namespace site_detail {
struct FusionGrid;
struct KeptFrame;
}

struct SiteOptions {
  double cell = 0;                 //!< m, cell of the fused height field; 0: the first frame's median pixel footprint
  double max_incidence_deg = 60;   //!< samples seen at more than this from the body normal (either camera) are not fused
  bool register_frames = true;     //!< align each frame to the fused surface before fusing it
  int register_stride = 4;         //!< px, every this many rows and columns take part in the alignment
  int register_iterations = 15;
  double min_overlap = 0.2;        //!< a frame must fall on fused skin with at least this share of its samples
  /** m: a frame whose alignment moves its samples by more than this from the pose given (RMS over the frame) is
   *  not trusted (left out, named): a registration that slid along the body is worse than the pose it started from. */
  double max_correction = 5e-3;
  double seam_block = 2e-3;        //!< m, block size of the seam measure (wider than the matcher window's correlation)
  /** refine every fused frame's pose jointly against all the frames it overlaps (a pose graph over the seam blocks,
   *  Ceres) and fuse the site again from the refined poses, before it is measured. Off by default: after the
   *  registration it changed no plaque on the rendered sweeps and let the poses slide along the limb (docs/site.md) */
  bool pose_graph = false;
  void validate() const;           //!< throws std::invalid_argument naming the option
};

/** @brief The keys of SiteOptions (config/site.yaml lists each with its default). */
const std::vector<std::string>& siteOptionKeys();
/** @brief Sets one option from its text value. @throws std::invalid_argument naming an unknown key or a bad value. */
void setSiteOption(SiteOptions* o, const std::string& key, const std::string& value);
/** @brief One option as text (the form setSiteOption reads). */
std::string getSiteOption(const SiteOptions& o, const std::string& key);
/** @brief The keys of a YAML file (config/site.yaml's form) over `o`. @throws std::invalid_argument naming the file
 *  or the key. */
void applySiteOptions(SiteOptions* o, const std::string& path);

/** @brief The body surface the site is unrolled on: world <-> (u, v, w). */
struct SiteSurface {
  std::string model = "plane";  //!< "cylinder" (a limb) or "plane"
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  //!< cylinder: its axis; plane: its normal (towards the first camera)
  Eigen::Vector3d e1 = Eigen::Vector3d::UnitX(), e2 = Eigen::Vector3d::UnitY();  //!< plane: in-plane axes; cylinder: theta = atan2(e2 . d, e1 . d)
  double radius = 0;            //!< m, the cylinder's mean radius (v = radius * theta)
  Eigen::Vector3d toSurface(const Eigen::Vector3d& X) const;
  Eigen::Vector3d toWorld(const Eigen::Vector3d& uvw) const;
  /** Unit direction in which w grows at (u, v) (radial; the plane's normal). */
  Eigen::Vector3d outward(const Eigen::Vector3d& uvw) const;
  /** Unit tangents along u and along v at (u, v) (world), for the fused surface's normal. */
  void tangents(const Eigen::Vector3d& uvw, Eigen::Vector3d* tu, Eigen::Vector3d* tv) const;
};

/** @brief What became of one frame. */
struct SiteFrame {
  int index = 0;
  double stamp = 0;
  bool fused = false;
  std::string reason;              //!< why it was left out (empty when fused)
  long samples = 0;                //!< samples fused
  double overlap = 0;              //!< share of its samples on skin fused before it
  double seam_rms = 0;             //!< m, RMS difference to the fused surface over seam blocks (NaN: no overlap)
  double seam_noise = 0;           //!< m, the RMS that the stated sigmas alone would give (independent samples)
  double seam_excess = 0;          //!< m, sqrt(max(0, seam_rms^2 - seam_noise^2)): the disagreement beyond the noise
  /** m: the RMS of the plane (offset and tilts) that best fits the block differences, each weighted by its noise:
   *  the disagreement a pose error leaves, measured through the noise (NaN with fewer than 10 blocks) */
  double seam_rigid = 0;
  double seconds_register = 0, seconds_fuse = 0;
  int seam_blocks = 0;
  double correction_rms = 0;       //!< m, how far the registration moved its samples from the given pose
  int registration_iterations = 0;
  Eigen::Isometry3d pose_given = Eigen::Isometry3d::Identity(), pose = Eigen::Isometry3d::Identity();
  Eigen::Vector3d right_centre = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());  //!< camera frame
  std::vector<induration::Plaque> plaques;  //!< its own measurement's plaques (its camera frame)
};

struct SitePlaque {
  int id = 0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  //!< m, world
  double top_height = 0, top_height_sigma = 0, mean_height = 0, max_height = 0;  //!< m
  double area = 0;                 //!< m^2 on the body
  double volume = 0;               //!< m^3
  int pasi_class = 0;
  double measured_share = 0;       //!< share of its footprint with a fused height
  int views = 0;                   //!< frames that found it on their own
  std::vector<double> view_tops;   //!< m, those frames' top heights
  double spread = 0;               //!< m, standard deviation of view_tops (0 with fewer than 2 views)
  double best_incidence_deg = 90;  //!< the smallest larger-of-both-cameras incidence any frame had at its centroid
  int frames_within_45 = 0;        //!< frames that saw its centroid within 45 deg in both cameras
};

/** @brief What the pose graph did (SiteOptions::pose_graph): frames' offsets from the fused surface over seam blocks,
 *  compared pair by pair wherever two frames share a block. */
struct SitePoseGraph {
  bool run = false, used = false, converged = false;
  int frames = 0, pairs = 0, iterations = 0, passes = 0;  //!< passes: summaries, solve and fusion again
  long blocks = 0;                 //!< block comparisons (residuals)
  double rms_before = 0, rms_after = 0;  //!< m, RMS of the pairs' block differences before the first pass, after the last
  double seconds = 0;              //!< s, summaries, solve and the fusion again
  std::string message;             //!< the solver's
};

struct SiteResult {
  SiteSurface surface;
  double cell = 0;                 //!< m
  std::string body_model;          //!< the body model fitted to the fused surface ("cylinder+fourier4", "plane+quadratic")
  double body_rms = 0;             //!< m, robust scatter of the healthy skin about it
  std::vector<SitePlaque> plaques;
  /** raised regions no pair saw within 45 deg in both cameras: reported apart, with their figures, never dropped */
  std::vector<SitePlaque> grazing;
  std::vector<std::string> warnings;
  int frames_fused = 0, frames_left_out = 0;
  double seam_rms = 0;             //!< m, RMS over the fused frames' seam blocks
  double seam_noise = 0, seam_excess = 0, seam_rigid = 0;  //!< m, as SiteFrame's, over all the blocks
  SitePoseGraph pose_graph;
  double seconds_measure = 0;      //!< s, the site measurement
  /** The unrolled maps (rows v, columns u, the crop of the fused cells): heights above the body model (m, NaN
   *  unknown), their sigma (m), frames that contributed, plaque labels; u0, v0 the coordinates of cell (0, 0)'s centre. */
  cv::Mat height, sigma, frames, labels;
  double u0 = 0, v0 = 0;
  cv::Mat world_xyz;               //!< CV_32FC3 world point of every known cell
  double fused_area = 0;           //!< m^2 of body with a fused height
  induration::IndurationResult flat;  //!< the measurement of the unrolled map
};

/** @brief A quick look at the site fused so far, for the live view (coarser than the fused cells; no plaques). */
struct SitePreview {
  std::string model;               //!< the body surface ("cylinder" or "plane"); empty before the first frame
  double cell = 0;                 //!< m, the preview's cell (a whole number of fused cells)
  double u0 = 0, v0 = 0;           //!< m, (u, v) of cell (0, 0)'s centre
  /** The whole grid (around a limb: its whole turn, so what was never seen shows too), rows v, columns u:
   *  the height above a smooth body model fitted to what is fused (m, NaN unknown; plaques not excluded, so it
   *  is a picture, not the measurement), the mean sigma of the fused cells in it (m), the most frames any of
   *  them had (0: not covered), and the world point (NaN unknown). */
  cv::Mat height, sigma, frames, world_xyz;
  int frames_fused = 0;
};

class SiteFusion {
 public:
  /** @throws std::invalid_argument for bad options. */
  SiteFusion(const SiteOptions& options, const induration::IndurationOptions& induration);
  ~SiteFusion();
  SiteFusion(const SiteFusion&) = delete;
  SiteFusion& operator=(const SiteFusion&) = delete;

  /**
   * @brief Fuses one frame.
   * @param cloud its organised cloud (left optical frame), with sigma and the right camera's centre
   * @param own its own induration measurement (its reference chooses the body surface on the first frame; its
   *        plaques are the views)
   * @param T_W_C its left optical frame's pose in `world`, as given (SLAM, gyro, a recorded pose topic)
   * @return the frame's record (fused or why not)
   */
  const SiteFrame& add(const geometry::DenseCloud& cloud, const induration::IndurationResult& own,
                       const Eigen::Isometry3d& T_W_C, double stamp);
  /** @brief A frame the door could not measure (a dropped or unreadable image): recorded, not fused. */
  void skip(double stamp, const std::string& reason);
  const std::vector<SiteFrame>& frames() const { return frames_; }
  bool empty() const;
  /** @brief The pose graph (SiteOptions::pose_graph): refines the fused frames' poses jointly and fuses the site
   *  again from them (their seams then say how they agree); the frames' records get the refined poses. Called
   *  before measuring a whole sweep; a no-op with the option off or fewer than two frames fused. */
  const SitePoseGraph& refine();
  /** @brief Measures the site fused so far (may be called at any time). */
  SiteResult measure() const;
  /** @brief The site fused so far on at most about `max_cells` preview cells (SitePreview); empty before the
   *  first frame. Fast (a fraction of a second at full resolution): for the live view after every frame. */
  SitePreview preview(int max_cells = 250000) const;

 private:
  SiteOptions options_;
  induration::IndurationOptions induration_;
  std::vector<SiteFrame> frames_;
  site_detail::FusionGrid* grid_ = nullptr;
  std::vector<std::unique_ptr<site_detail::KeptFrame>> kept_;  //!< the fused frames' samples (for the pose graph)
  void refuse(const std::vector<Eigen::Isometry3d>& poses);    //!< the kept frames fused again from these poses
  SitePoseGraph graph_;
};

/** @brief Residual of a world point X against the fused surface's tangent plane (P, n): n . (X - P), and its
 *  derivative with respect to a pose perturbation X -> Exp(dphi) X + dt (dphi, dt), exposed for the Jacobian test. */
double pointToPlane(const Eigen::Vector3d& X, const Eigen::Vector3d& P, const Eigen::Vector3d& n,
                    Eigen::Matrix<double, 1, 6>* J);

/** @brief Frames fused per cell (CV_8U) in false colour (0: dark grey), at most `max_width` px wide, with a legend
 *  (site_coverage.png and the live site/coverage image). */
cv::Mat coverageImage(const cv::Mat& frames, int max_width = 1600);

/** @brief The site's results (docs/results.md "Site"): site.yaml, site_height_map.png, site_coverage.png,
 *  site_surface.ply into `dir`; `frame` names the world frame the poses were given in. @throws std::runtime_error naming a file that cannot be written. */
void writeSiteResults(const std::string& dir, const SiteResult& r, const std::vector<SiteFrame>& frames,
                      const std::string& source, const std::vector<std::string>& command_line,
                      const std::string& frame = "world");

}  // namespace site
}  // namespace skin3d
