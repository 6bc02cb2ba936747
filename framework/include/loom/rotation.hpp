#pragma once
// The rotation matrix of a turn by `angle` about the unit axis a (Rodrigues), row-major:
// R = cos I + sin [a]x + (1 - cos) a a^T. Shared by the pins' rigid placements and the
// self-collision lists' frame.

#include <cmath>

namespace loom {

inline void axis_angle_matrix(const double a[3], double angle, double R[9]) {
  const double c = std::cos(angle), s = std::sin(angle), oc = 1.0 - c;
  R[0] = c + oc * a[0] * a[0];
  R[1] = oc * a[0] * a[1] - s * a[2];
  R[2] = oc * a[0] * a[2] + s * a[1];
  R[3] = oc * a[1] * a[0] + s * a[2];
  R[4] = c + oc * a[1] * a[1];
  R[5] = oc * a[1] * a[2] - s * a[0];
  R[6] = oc * a[2] * a[0] - s * a[1];
  R[7] = oc * a[2] * a[1] + s * a[0];
  R[8] = c + oc * a[2] * a[2];
}

}  // namespace loom
