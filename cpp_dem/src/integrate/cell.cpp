// The periodic cell (bodies/cell.hpp): setting it, the mean field's step (applied to the
// bodies by the integration pass, to the cell after it), wrapping bodies into the cell, and
// the cell stress.
#include <cmath>
#include <sstream>

#include "cpp_dem/core/parallel.hpp"
#include "cpp_dem/scene.hpp"

namespace cpp_dem {

namespace {
std::string mat_str(const Mat3& m) {
  std::ostringstream os;
  os.precision(6);
  os << "[";
  for (int r = 0; r < 3; ++r) {
    os << (r ? ", [" : "[");
    for (int c = 0; c < 3; ++c) os << (c ? ", " : "") << m(r, c);
    os << "]";
  }
  os << "]";
  return os.str();
}

const char* axis_name(int a) { return a == 0 ? "x" : a == 1 ? "y" : "z"; }
}  // namespace

void Scene::set_periodic_cell(const Mat3& h, const std::array<bool, 3>& periodic) {
  if (!h.allFinite() || !(h.determinant() > 0))
    throw ParameterError("cell=" + mat_str(h) +
                         ": must be finite with det > 0 (columns: the cell vectors, m, "
                         "right-handed)");
  if (!periodic[0] && !periodic[1] && !periodic[2])
    throw ParameterError("periodic=(false, false, false): at least one axis must be periodic");
  if (has_clumps())
    throw ParameterError("periodic cell: the scene has clumps; clumps in a periodic cell are "
                         "not supported yet");
  if (has_grid())
    throw ParameterError("periodic cell: the scene has a geogrid; a geogrid in a periodic cell "
                         "is not supported yet");
  if (!cylinder_walls_.empty() || !mesh_walls_.empty())
    throw ParameterError(std::string("periodic cell: the scene has ") +
                         (mesh_walls_.empty() ? "cylindrical" : "mesh") +
                         " walls; they are not supported in a periodic cell");
  for (int a = 0; a < 3; ++a) {
    if (!periodic[a]) continue;
    for (const Wall& w : walls_)
      if (w.axis == a)
        throw ParameterError(std::string("periodic[") + axis_name(a) +
                             "]=true: the scene has a wall normal to " + axis_name(a) +
                             "; walls may only be normal to axes that are not periodic");
  }
  cell_.on = true;
  cell_.periodic = periodic;
  cell_.h = cell_.h_ref = cell_.h_at_build = h;
  cell_.vel_grad.setZero();
  dirty_ = true;
}

void Scene::set_velocity_gradient(const Mat3& l) {
  if (!cell_.on)
    throw ParameterError("velocity_gradient: the scene has no periodic cell "
                         "(set_periodic_cell first)");
  if (!l.allFinite())
    throw ParameterError("velocity_gradient=" + mat_str(l) + ": must be finite (1/s)");
  for (int a = 0; a < 3; ++a) {
    if (cell_.periodic[a]) continue;
    for (int b = 0; b < 3; ++b)
      if (l(a, b) != 0 || l(b, a) != 0)
        throw ParameterError("velocity_gradient=" + mat_str(l) + ": row and column " +
                             axis_name(a) + " must be 0 (the cell is not periodic along " +
                             axis_name(a) + "; walls move the bodies there)");
  }
  cell_.vel_grad = l;
}

void Scene::set_mean_spin(bool on) { cell_.mean_spin = on; }

void Scene::refresh_image_offsets() {
  for (int k = 0; k < 27; ++k) {
    const Vec3 s(k / 9 - 1, (k / 3) % 3 - 1, k % 3 - 1);
    const Vec3 o = cell_.h * s;
    image_offset_[k] = {o[0], o[1], o[2], 0.0};
  }
}

void Scene::wrap_into_cell() {
  const Mat3 inv = cell_.h.inverse();
  const int n = num_bodies();
  for (int b = 0; b < n; ++b) {
    const Vec3 s = inv * bodies_.pos[b];
    Vec3 w = Vec3::Zero();
    bool any = false;
    for (int a = 0; a < 3; ++a) {
      if (!cell_.periodic[a]) continue;
      w[a] = std::floor(s[a]);
      any = any || w[a] != 0;
    }
    if (!any) continue;
    bodies_.pos[b] -= cell_.h * w;
    if (bodies_.image.empty()) bodies_.image.assign(n, {0, 0, 0});  // (the first wrap)
    for (int a = 0; a < 3; ++a) bodies_.image[b][a] += static_cast<int>(w[a]);
  }
}

Mat3 Scene::pair_stress_sum() const {
  Mat3 s = Mat3::Zero();
  const int nrows = static_cast<int>(pair_ioff_.size()) - 1;
  for (int i = 0; i < nrows; ++i) {
    for (int k = pair_ioff_[i]; k < pair_ioff_[i + 1]; ++k) {
      if (cand_slot(k) < 0 || !pairs_[cand_slot(k)].active) continue;
      const Vec3 l = bodies_.pos[cand_second(k)] + pair_shift(k) - bodies_.pos[i];
      s += pair_force(k) * l.transpose();
    }
  }
  // Bonds (contact and parallel bonds: a geogrid of bonded spheres in the cell), b at the
  // image the bond sees.
  for (const Bond& b : bonds_) {
    const Vec3 l = bodies_.pos[b.b] + bond_shift(b) - bodies_.pos[b.a];
    s += b.force_b * l.transpose();
  }
  return s;
}

Mat3 Scene::cell_stress() const {
  if (!cell_.on)
    throw ParameterError("cell_stress: the scene has no periodic cell (use "
                         "measure.love_weber_stress with a volume)");
  return pair_stress_sum() / cell_.volume();
}

MeanFieldStep Scene::mean_field_step() const {
  MeanFieldStep m;
  m.a = cell_.step_map(dt_);
  m.fb = m.a * cell_.h * cell_.h_at_build.inverse();
  const Vec3 w = cell_.spin();
  const Real angle = w.norm() * dt_;
  if (angle > 0) {
    m.rotate = true;
    m.spin = Quat(Eigen::AngleAxisd(angle, w / w.norm()));
  }
  return m;
}

void Scene::advance_cell() {
  if (cell_.vel_grad.isZero(0)) return;
  cell_.h = cell_.step_map(dt_) * cell_.h;
}

}  // namespace cpp_dem
