// The clump API of the scene: adding clumps, their state setters, and placing the members.
#include <cmath>
#include <sstream>
#include <string>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

int Scene::add_clump(const std::vector<Vec3>& local, const std::vector<Real>& radius,
                     int material, Real mass, const Vec3& inertia, const Vec3& com,
                     const Quat& ori, Real stiffness_radius) {
  this->material(material);
  if (cell_.on)
    throw ParameterError("clumps: the scene has a periodic cell; clumps in a periodic cell are "
                         "not supported yet");
  if (local.empty()) throw ParameterError("members: empty; a clump needs at least one sphere");
  if (local.size() != radius.size())
    throw ParameterError("radius: has " + std::to_string(radius.size()) + " values for " +
                         std::to_string(local.size()) + " member centres");
  for (size_t k = 0; k < local.size(); ++k) {
    require(std::isfinite(radius[k]) && radius[k] > 0, "radius", radius[k], "must be > 0 (m)");
    if (!local[k].allFinite())
      throw ParameterError("member centre " + std::to_string(k) + ": must be finite (m)");
  }
  require(std::isfinite(mass) && mass > 0, "mass", mass, "must be > 0 (kg)");
  for (int a = 0; a < 3; ++a)
    require(std::isfinite(inertia[a]) && inertia[a] > 0, "inertia", inertia[a],
            "principal moments must be > 0 (kg m^2)");
  if (!com.allFinite()) {
    std::ostringstream os;
    os << "position=(" << com[0] << ", " << com[1] << ", " << com[2]
       << ") of the clump (its centre of mass): must be 3 finite numbers (m)";
    throw ParameterError(os.str());
  }
  require(std::isfinite(stiffness_radius) && stiffness_radius >= 0, "stiffness_radius",
          stiffness_radius, "must be >= 0 (m; 0: the members' own radii)");
  const Real qn = ori.norm();
  require(std::isfinite(qn) && std::abs(qn - 1) < 1e-6, "orientation norm", qn,
          "must be a unit quaternion");
  const int c = clumps_.size();
  if (clumps_.member_off.empty()) clumps_.member_off.push_back(0);
  clumps_.pos.push_back(com);
  clumps_.vel.push_back(Vec3::Zero());
  clumps_.angvel.push_back(Vec3::Zero());
  clumps_.angmom.push_back(Vec3::Zero());
  clumps_.ori.push_back(ori.normalized());
  clumps_.rot.push_back(clumps_.ori.back().toRotationMatrix());
  clumps_.force.push_back(Vec3::Zero());
  clumps_.torque.push_back(Vec3::Zero());
  if (!clumps_.ext_force.empty()) {  // (allocated when one is first set)
    clumps_.ext_force.push_back(Vec3::Zero());
    clumps_.ext_torque.push_back(Vec3::Zero());
  }
  clumps_.mass.push_back(mass);
  clumps_.inertia.push_back(inertia);
  clumps_.stiffness_radius.push_back(stiffness_radius);
  clumps_.blocked.push_back(DOF_NONE);
  clumps_.inertia_scale.push_back(1.0);
  if (track_energy_ || !clumps_.ke.empty()) clumps_.size_energy();
  // Members: spheres whose masses share the clump's by volume (they carry its weight in the
  // integration pass; the clump pass applies it at the centre of mass).
  Real vsum = 0;
  for (Real r : radius) vsum += r * r * r;
  for (size_t k = 0; k < local.size(); ++k) {
    const Real r = radius[k];
    const Real m = mass * (r * r * r / vsum);
    const int slot = num_bodies();
    push_body(com, r, m, 0.4 * m * r * r, material, BODY_SPHERE);
    bodies_.clump[slot] = c;
    bodies_.blocked[slot] = DOF_ALL;  // moved by the clump pass, not as a free body
    clumps_.member.push_back(slot);
    clumps_.member_local.push_back(local[k]);
  }
  clumps_.member_off.push_back(static_cast<int>(clumps_.member.size()));
  place_members(c);
  min_radius_ = -1;
  dirty_ = true;
  return c;
}

void Scene::check_clump(int c) const {
  if (c < 0 || c >= num_clumps())
    throw ParameterError("clump=" + std::to_string(c) + ": no such clump (the scene has " +
                         std::to_string(num_clumps()) + ")");
}

std::vector<int> Scene::clump_members(int c) const {
  check_clump(c);
  std::vector<int> ids;
  for (int e = clumps_.member_off[c]; e < clumps_.member_off[c + 1]; ++e)
    ids.push_back(id_of(clumps_.member[e]));
  return ids;
}

void Scene::place_members(int c) { cpp_dem::place_members(clumps_, bodies_, c); }

void Scene::set_clump_state(int c, const Vec3& pos, const Quat& ori, const Vec3& vel,
                            const Vec3& angvel) {
  check_clump(c);
  if (!pos.allFinite()) throw ParameterError("position: must be finite (m)");
  if (!vel.allFinite()) throw ParameterError("velocity: must be finite (m/s)");
  if (!angvel.allFinite()) throw ParameterError("angular_velocity: must be finite (rad/s)");
  const Real qn = ori.norm();
  require(std::isfinite(qn) && std::abs(qn - 1) < 1e-6, "orientation norm", qn,
          "must be a unit quaternion");
  clumps_.pos[c] = pos;
  clumps_.ori[c] = ori.normalized();
  clumps_.vel[c] = vel;
  clumps_.angvel[c] = angvel;
  place_members(c);  // (and the rotation matrix of the new orientation)
  const Mat3& rot = clumps_.rot[c];
  clumps_.angmom[c] = rot * clumps_.inertia[c].cwiseProduct(rot.transpose() * angvel);
  dirty_ = true;
}

void Scene::set_clump_blocked(int c, std::uint8_t mask) {
  check_clump(c);
  if (mask > DOF_ALL)
    throw ParameterError("blocked=" + std::to_string(mask) + ": must be a mask of x y z rx ry rz");
  clumps_.blocked[c] = mask;
  ds_stale_ = ds_on_;  // (its inertia factor follows at the next step's start)
}

void Scene::set_clump_external(int c, const Vec3& force, const Vec3& torque) {
  check_clump(c);
  if (!force.allFinite()) throw ParameterError("force: must be finite (N)");
  if (!torque.allFinite()) throw ParameterError("torque: must be finite (N m)");
  if (clumps_.ext_force.empty()) {
    clumps_.ext_force.assign(clumps_.pos.size(), Vec3::Zero());
    clumps_.ext_torque.assign(clumps_.pos.size(), Vec3::Zero());
  }
  clumps_.ext_force[c] = force;
  clumps_.ext_torque[c] = torque;
}

}  // namespace cpp_dem
