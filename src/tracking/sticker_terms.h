#pragma once
/// One sticker's corners in the body tracker's Gauss-Newton normal
/// equations, with the sticker free to move along its normal (breathing).
///
/// A sticker on the chest or abdomen rises and falls with the breathing; the
/// session measured by how much (1 sigma, `motion_m`). Its four corners
/// move together by d along the sticker's normal, d ~ N(0, motion_m^2):
/// their whitened residuals r then have covariance I + motion_m^2 b b^T,
/// b = dr/dd, whose inverse is I - k b b^T with k = 1 / (1/motion_m^2 +
/// b^T b) (Sherman-Morrison). The sticker so keeps holding the pose across
/// its normal and gives up what breathing blurs along it; motion_m = 0 is
/// the plain sum.

#include <Eigen/Core>

namespace arpos {

/// Rows of a sticker's four corners (two each); unused rows stay zero.
using StickerResiduals = Eigen::Matrix<double, 8, 1>;
using StickerJacobian = Eigen::Matrix<double, 8, 6>;

/// Adds J^T W J to `H`, J^T W r to `g` and r^T W r to `chi2`, W as in the
/// file comment. r: whitened residuals; J: dr/d(pose); b: dr/dd.
inline void AddStickerTerms(const StickerResiduals& r, const StickerJacobian& J, const StickerResiduals& b,
                            double motion_m, Eigen::Matrix<double, 6, 6>* H, Eigen::Matrix<double, 6, 1>* g,
                            double* chi2) {
  *H += J.transpose() * J;
  *g += J.transpose() * r;
  *chi2 += r.squaredNorm();
  if (!(motion_m > 0)) return;
  const double k = 1.0 / (1.0 / (motion_m * motion_m) + b.squaredNorm());
  const Eigen::Matrix<double, 6, 1> Jb = J.transpose() * b;
  const double br = b.dot(r);
  *H -= k * Jb * Jb.transpose();
  *g -= k * Jb * br;
  *chi2 -= k * br * br;
}

}  // namespace arpos
