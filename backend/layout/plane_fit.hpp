// SPDX-License-Identifier: Apache-2.0
#pragma once

// Least-squares plane fitting from accumulated first and second moments (reference §4.4: the
// centroid and the eigenvector of the smallest eigenvalue of the 3x3 covariance).
//
// Thread-safety: value types; const access from several threads is safe, a write needs
// exclusive access; the free functions are pure.

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace plumb::layout {

struct PlaneFitResult {
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  ///< unit
    double d = 0.0;                                     ///< n.x + d = 0
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    /// lambda_min / (lambda_0 + lambda_1 + lambda_2): 0 for a perfect plane, 1/3 for isotropic.
    double curvature = 0.0;
    double rms_m = 0.0;  ///< sqrt(lambda_min): RMS distance of the points from the plane
    double weight = 0.0;
    bool valid = false;  ///< false with fewer than 3 points or a degenerate (collinear) spread
};

/// Weighted moments of a point set.
class PlaneMoments {
  public:
    void add(const Eigen::Vector3d& p, double w = 1.0) {
        w_ += w;
        s_ += w * p;
        ss_ += w * p * p.transpose();
        ++n_;
    }
    void add(const PlaneMoments& o) {
        w_ += o.w_;
        s_ += o.s_;
        ss_ += o.ss_;
        n_ += o.n_;
    }
    long count() const { return n_; }
    double weight() const { return w_; }
    Eigen::Vector3d mean() const { return w_ > 0 ? Eigen::Vector3d(s_ / w_) : s_; }

    PlaneFitResult fit() const {
        PlaneFitResult r;
        r.weight = w_;
        if (n_ < 3 || w_ <= 0.0) return r;
        r.centroid = s_ / w_;
        const Eigen::Matrix3d cov = ss_ / w_ - r.centroid * r.centroid.transpose();
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
        const Eigen::Vector3d ev = es.eigenvalues().cwiseMax(0.0);
        const double sum = ev.sum();
        if (!(sum > 0.0) || ev(1) < 1e-12 * sum) return r;  // collinear or a single point
        r.normal = es.eigenvectors().col(0).normalized();
        r.d = -r.normal.dot(r.centroid);
        r.curvature = ev(0) / sum;
        r.rms_m = std::sqrt(ev(0));
        r.valid = true;
        return r;
    }

    /// The offset d minimising the weighted squared distances for a fixed unit normal.
    double offsetFor(const Eigen::Vector3d& normal) const {
        return w_ > 0 ? -normal.dot(s_ / w_) : 0.0;
    }

  private:
    double w_ = 0.0;
    Eigen::Vector3d s_ = Eigen::Vector3d::Zero();
    Eigen::Matrix3d ss_ = Eigen::Matrix3d::Zero();
    long n_ = 0;
};

}  // namespace plumb::layout
