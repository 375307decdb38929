// SPDX-License-Identifier: BSD-3-Clause
// The only PCL user of the core (PCL's headers are heavy): RANSAC plane of a point subsample, the starting
// point of the healthy-skin reference (induration.cpp refines it robustly).
#include "reference_ransac.h"

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/sample_consensus/ransac.h>
#include <pcl/sample_consensus/sac_model_plane.h>

namespace skin3d {
namespace induration {

bool ransacPlane(const std::vector<Eigen::Vector3f>& points, double threshold, Eigen::Vector4d* plane, int* inliers) {
  if (points.size() < 3) return false;
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  cloud->reserve(points.size());
  for (const auto& p : points) cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  pcl::SampleConsensusModelPlane<pcl::PointXYZ>::Ptr model(new pcl::SampleConsensusModelPlane<pcl::PointXYZ>(cloud));
  pcl::RandomSampleConsensus<pcl::PointXYZ> ransac(model, threshold);
  ransac.setMaxIterations(1000);
  ransac.setProbability(0.999);
  if (!ransac.computeModel()) return false;
  std::vector<int> in;
  ransac.getInliers(in);
  Eigen::VectorXf c;
  ransac.getModelCoefficients(c);
  if (c.size() != 4) return false;
  // least squares on the inliers, then again on the points within a quarter of the threshold: a plane through
  // three samples may be tilted by up to the threshold across the view
  for (double t : {threshold, 0.25 * threshold}) {
    std::vector<int> sel;
    model->selectWithinDistance(c, t, sel);
    if (sel.size() < 3) break;
    Eigen::VectorXf refined;
    model->optimizeModelCoefficients(sel, c, refined);
    if (refined.size() == 4 && refined.allFinite()) c = refined;
    in = sel;
  }
  *plane = c.cast<double>();
  const double n = plane->head<3>().norm();
  if (!(n > 0)) return false;
  *plane /= n;
  *inliers = static_cast<int>(in.size());
  return true;
}

}  // namespace induration
}  // namespace skin3d
