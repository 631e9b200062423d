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

/// The breathing the moving stickers share. Treated one by one, N stickers
/// that rise together pin their common rise to motion_m / sqrt(N), and the
/// pose follows the chest (measured on a simulated l515 case with 3.5 mm of
/// breathing: the patient's vertical error 0.71 times the chest's rise).
/// But the chest rises as one: in a frame every moving sticker is moved
/// along its normal by beta * its motion_m, with one beta for all of them,
/// beta ~ N(0, beta_sigma^2); beta is a seventh unknown, eliminated from the
/// pose's normal equations (Schur complement). AddStickerTerms accumulates
/// its column; Eliminate folds it into H, g and chi2.
struct SharedBreathing {
  Eigen::Matrix<double, 6, 1> h = Eigen::Matrix<double, 6, 1>::Zero();  ///< J^T W db/dbeta
  double hbb = 0;                                                       ///< (dr/dbeta)^T W dr/dbeta
  double gb = 0;                                                        ///< (dr/dbeta)^T W r
  int stickers = 0;

  void Eliminate(double beta_sigma, Eigen::Matrix<double, 6, 6>* H, Eigen::Matrix<double, 6, 1>* g,
                 double* chi2) const {
    if (stickers == 0 || !(beta_sigma > 0)) return;
    const double hbb_prior = hbb + 1.0 / (beta_sigma * beta_sigma);
    *H -= h * h.transpose() / hbb_prior;
    *g -= h * gb / hbb_prior;
    *chi2 -= gb * gb / hbb_prior;
  }
};

/// Adds J^T W J to `H`, J^T W r to `g` and r^T W r to `chi2`, W as in the
/// file comment. r: whitened residuals; J: dr/d(pose); b: dr/dd. A moving
/// sticker (motion_m > 0) also adds its share of the breathing they all
/// share to `shared`, if given.
inline void AddStickerTerms(const StickerResiduals& r, const StickerJacobian& J, const StickerResiduals& b,
                            double motion_m, Eigen::Matrix<double, 6, 6>* H, Eigen::Matrix<double, 6, 1>* g,
                            double* chi2, SharedBreathing* shared = nullptr) {
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
  if (shared == nullptr) return;
  // The shared rise's column, motion_m * b, through W: W b = (1 - k b^T b) b.
  const double wb = 1 - k * b.squaredNorm();
  shared->h += motion_m * wb * Jb;
  shared->hbb += motion_m * motion_m * wb * b.squaredNorm();
  shared->gb += motion_m * wb * br;
  ++shared->stickers;
}

}  // namespace arpos
