// Controllers for granular samples: servo walls, the triaxial (box) controller, and radius
// growth under stress control (001 §4.3.1, the "grow factor"; the expansion stage of REFD,
// 000 §2.3). Each is a Controller (scene.hpp): it runs at the start of a step, sees the wall
// forces of the previous step and touches only what it owns.
//
// Sign convention: stresses are compressive positive (Pa); strains are compressive positive.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

/// State a checkpoint saves and restores (checkpoint.cpp): controllers with history implement
/// it, so a restart continues bitwise.
class StatefulController {
 public:
  virtual ~StatefulController() = default;
  virtual std::vector<Real> save_state() const = 0;
  virtual void load_state(const std::vector<Real>& s) = 0;
};

/// Normal stress on a wall, Pa, compressive positive: -sense * F_axis / area.
Real wall_normal_stress(const Wall& w, Real area);

/// Sum of the tangent normal stiffnesses of the active sphere contacts of a wall (kind
/// ContactKind::Cylinder: of cylindrical wall `wall`), N/m.
Real wall_contact_stiffness(const Scene& s, int wall, ContactKind kind = ContactKind::Wall);

/// Servo law of one wall (Yade's TriaxialStressController / PFC servo, with the gain from the
/// measured stiffness): the wall displacement towards the spheres over the next `period`
/// steps is alpha (sigma_target - sigma) A / k, k the sum of the normal stiffnesses of the
/// wall's contacts (N/m). Returns the velocity along the wall's inward normal, m/s, capped to
/// [-max_speed, max_speed]; without contacts (k = 0) the wall approaches at +max_speed when
/// the target is not reached (and stays when it is, sigma_target = 0).
Real servo_speed(Real sigma_target, Real sigma, Real area, Real stiffness, Real dt, int period,
                 Real gain, Real max_speed);

/// A stress-controlled wall that has reached its target and then drifts from it at its
/// speed cap. Once the stress has been within `tolerance` of the target (the wall holds it),
/// a run of consecutive calls at the cap is an episode, and a call of an episode whose stress
/// error has grown by more than `tolerance` x the target since the episode began is counted,
/// with the target, the reached stress and the cap. (Before the target is first reached, as
/// while a preparation compacts a loose sample at the cap, nothing is counted; a new target
/// starts over.) The Python face turns a count into a warning naming them after each run,
/// or an error if asked.
struct LimitWatch {
  static constexpr Real tolerance = 0.05;  ///< relative stress error, -
  long count = 0;        ///< such calls since the last clear
  Real target = 0;       ///< Pa, at the last such call
  Real reached = 0;      ///< Pa, at the last such call
  Real cap = 0;          ///< m/s, at the last such call
  bool held = false;     ///< the stress has been within tolerance of the current target
  Real goal_seen = -1;   ///< the target the watch follows, Pa
  Real episode_error = -1;  ///< |sigma - goal| when the current episode began, Pa (-1: none)
  // A target never reached (ServoWall): calls and calls at the cap since clear_run(), the
  // stress and cap at the last call, and whether the current target was reported unmet.
  long run_calls = 0;      ///< calls since the last clear_run
  long run_cap_calls = 0;  ///< of those, calls at the cap
  Real last_sigma = 0;     ///< Pa, at the last call
  Real last_cap = 0;       ///< m/s (or 1/s), at the last call
  bool unmet_told = false; ///< the current target was reported as not reached
  /// Records one call: v the servo's speed (m/s), cap (m/s), sigma and goal (Pa).
  void observe(Real v, Real cap_speed, Real sigma, Real goal) {
    if (goal != goal_seen) {  // a new target: start over
      goal_seen = goal;
      held = false;
      episode_error = -1;
      unmet_told = false;
    }
    const Real err = std::abs(sigma - goal);
    const Real band = tolerance * std::max(std::abs(goal), 1.0);
    if (err <= band) held = true;
    const bool at_cap = std::abs(v) >= cap_speed * (1 - 1e-12);
    ++run_calls;
    if (at_cap) ++run_cap_calls;
    last_sigma = sigma;
    last_cap = cap_speed;
    if (!at_cap) {
      episode_error = -1;  // below the cap: the episode ends
      return;
    }
    if (episode_error < 0) episode_error = err;
    if (held && err > episode_error + band) {
      ++count;
      target = goal;
      reached = sigma;
      cap = cap_speed;
    }
  }
  void clear() { count = 0; }
  /// The current target has not been within `tolerance` of the stress at any call since it
  /// was set, and calls ran since clear_run(), and it was not reported yet.
  bool unmet() const { return run_calls > 0 && !held && !unmet_told; }
  /// Starts the count of calls over (after each run); `told`: the unmet target was reported.
  void clear_run(bool told) {
    run_calls = 0;
    run_cap_calls = 0;
    if (told) unmet_told = true;
  }
};

/// What a servo of one wall shares (ServoWall, CylinderServo): its target stress (Pa,
/// compressive positive), gain, speed cap, the contact stiffness at its last call and its
/// LimitWatch; its speed is servo_speed's.
class StressServo : public Controller {
 public:
  void set_max_speed(Real v);
  Real max_speed() const { return max_speed_; }
  void set_gain(Real g);
  Real gain() const { return gain_; }
  /// Contact stiffness measured at the last call, N/m.
  Real stiffness() const { return stiffness_; }
  /// Calls at the speed cap while off the target (see LimitWatch).
  const LimitWatch& limit() const { return limit_; }
  void clear_limit() { limit_.clear(); }
  /// Starts the count of calls towards a target not yet reached over (LimitWatch::clear_run).
  void clear_target_watch(bool told) { limit_.clear_run(told); }

 protected:
  /// target: Pa, >= 0 (its name in messages: field); gain: alpha in (0, 1] (fraction of the
  /// stiffness-predicted correction applied per period); max_speed: the cap, m/s (> 0).
  StressServo(Real target, const char* field, Real gain, Real max_speed);
  void set_target(Real target, const char* field);
  /// The speed into the grains (servo_speed, m/s) for the stress `measured` (Pa) on `area`
  /// (m^2) with contact stiffness `k` (N/m, kept), watched by the LimitWatch.
  Real speed(const Scene& scene, Real measured, Real area, Real k);
  LimitWatch limit_;
  Real target_, gain_, max_speed_;
  Real stiffness_ = 0;
};

/// One wall driven to a target normal stress by its velocity (the other walls are not
/// touched). The area is fixed (m^2) or, when `box_walls` holds the six walls of a box (order
/// x-, x+, y-, y+, z-, z+), recomputed every call from the current box dimensions.
class ServoWall : public StressServo {
 public:
  /// wall: wall id; target_stress: Pa, >= 0 (compressive); area: m^2 (> 0) or 0 when
  /// box_walls are given; gain, max_speed: StressServo's.
  ServoWall(int wall, Real target_stress, Real area, Real gain, Real max_speed,
            std::vector<int> box_walls = {});
  void apply(Scene& scene) override;

  void set_target_stress(Real sigma) { set_target(sigma, "target_stress"); }
  Real target_stress() const { return target_; }
  int wall() const { return wall_; }
  /// Wall area used at the last call, m^2.
  Real area() const { return area_; }
  /// Stress measured at the last call, Pa (compressive positive).
  Real measured_stress() const { return sigma_; }

 private:
  int wall_;
  Real area0_;
  std::vector<int> box_;
  Real area_ = 0, sigma_ = 0;
};

/// A cylindrical wall (Scene::add_cylinder_wall) driven to a target mean normal pressure on
/// its lateral surface (Pa, compressive positive) by the rate of its radius: each call sets
/// radial_velocity to -/+ gain (p_target - p) A / (k dt period) (inside: a pressure below the
/// target narrows the cylinder; outside: it widens it), capped to +-max_speed (m/s); p is the
/// wall's normal_force over its lateral area A = 2 pi R (hi - lo), k the summed normal
/// stiffness of its contacts (N/m). The cylinder must be finite.
class CylinderServo : public StressServo {
 public:
  CylinderServo(int cylinder, Real target_pressure, Real gain, Real max_speed);
  void apply(Scene& scene) override;

  void set_target_pressure(Real p) { set_target(p, "target_pressure"); }
  Real target_pressure() const { return target_; }
  int cylinder() const { return cylinder_; }
  /// Pressure measured at the last call, Pa (compressive positive).
  Real measured_pressure() const { return p_; }

 private:
  int cylinder_;
  Real p_ = 0;
};

/// A mesh wall (Scene::add_mesh_wall) driven as a whole along the unit `direction` (into the
/// grains) to a target normal stress (Pa, compressive positive) on `area` (m^2): each call
/// sets its velocity to v direction, v = gain (sigma_target - sigma) A / (k dt period) capped
/// to +-max_speed (m/s), sigma the spheres' push on it against `direction` over the area, k
/// the summed normal stiffness of its contacts (N/m). A loading plate or a footing.
class MeshServo : public StressServo {
 public:
  MeshServo(int mesh, Vec3 direction, Real target_stress, Real area, Real gain, Real max_speed);
  void apply(Scene& scene) override;

  void set_target_stress(Real sigma) { set_target(sigma, "target_stress"); }
  Real target_stress() const { return target_; }
  int mesh() const { return mesh_; }
  const Vec3& direction() const { return direction_; }
  Real area() const { return area_; }
  /// Stress measured at the last call, Pa (compressive positive).
  Real measured_stress() const { return sigma_; }

 private:
  int mesh_;
  Vec3 direction_;
  Real area_, sigma_ = 0;
};

/// A confining pressure on a surface of triangles between bodies (a flexible membrane of
/// PFacets: cpp_dem.build.membrane): every call sets the external force of each of its
/// nodes to the sum of a third of -p A_f over its triangles, A_f = (x1 - x0) x (x2 - x0) / 2
/// the triangle's area vector from the nodes' current positions (outward for nodes listed
/// anticlockwise seen from outside), p the pressure (Pa, compressive positive: it pushes the
/// surface inwards). So the load follows the area and the normal of each triangle as the
/// surface deforms. It owns its nodes' external forces: a force set on them otherwise is
/// replaced at the next call. The pressure's work is the external work of the energy balance.
class MembranePressure : public Controller {
 public:
  /// triangles: node body ids, three per triangle (outward order); pressure_pa: finite.
  MembranePressure(std::vector<std::array<int, 3>> triangles, Real pressure_pa);
  void apply(Scene& scene) override;
  void set_pressure(Real p);
  Real pressure() const { return pressure_; }
  const std::vector<std::array<int, 3>>& triangles() const { return tris_; }
  /// The nodes it loads (body ids, ascending).
  const std::vector<int>& nodes() const { return nodes_; }
  /// Sum of the triangles' areas at the last call, m^2.
  Real area() const { return area_; }
  /// Sum of the triangles' area vectors at the last call, m^2 (zero for a closed surface).
  const Vec3& area_vector() const { return area_vec_; }

 private:
  std::vector<std::array<int, 3>> tris_;
  std::vector<int> nodes_;
  std::vector<std::array<int, 3>> at_;  // each triangle's corners' places in nodes_
  std::vector<Vec3> force_;  // scratch, per node
  Real pressure_;
  Real area_ = 0;
  Vec3 area_vec_ = Vec3::Zero();
};

/// Bodies held to a planar wall, as a membrane's end ring is sealed to its platen: every call
/// gives each body the wall's velocity along the wall's axis, corrected by its offset from
/// where the wall has carried it since the first call over one step ((target - x) / dt), and
/// holds it still across the axis. The bodies' translations are blocked at the first call
/// (a blocked degree of freedom keeps its imposed velocity).
class PlatenClamp : public Controller, public StatefulController {
 public:
  /// wall: the planar wall's id; bodies: body ids (not clump members).
  PlatenClamp(int wall, std::vector<int> bodies);
  void apply(Scene& scene) override;
  int wall() const { return wall_; }
  const std::vector<int>& bodies() const { return bodies_; }
  /// Largest distance along the axis between a body and where the wall has carried it, at
  /// the last call, m.
  Real max_offset() const { return max_offset_; }
  /// Whether it has started, the wall's position then and the bodies' positions then: a
  /// restart goes on holding them where they were.
  std::vector<Real> save_state() const override;
  void load_state(const std::vector<Real>& st) override;

 private:
  int wall_;
  std::vector<int> bodies_;
  std::vector<Vec3> start_;  // the bodies' positions at the first call
  Real wall_start_ = 0;
  bool started_ = false;
  Real max_offset_ = 0;
};

/// Per-axis control of a box of six walls (order x-, x+, y-, y+, z-, z+): each axis is either
/// stress-controlled (both walls servo to the target normal stress, with the wall area
/// recomputed from the current box dimensions) or strain-rate-controlled (both walls move
/// inwards at rate L0 / 2 each, so the engineering strain (L0 - L) / L0 grows at `rate`, 1/s;
/// compression positive; rate 0 holds the walls still).
class TriaxialController : public Controller, public StatefulController {
 public:
  enum class Mode : int { Stress = 0, StrainRate = 1 };
  /// walls: the six box walls; gain, max_speed as ServoWall. The reference lengths L0 are
  /// the box dimensions now (reset with reset_strain()).
  TriaxialController(std::vector<int> walls, Real gain, Real max_speed);
  void apply(Scene& scene) override;

  /// Stress control of an axis (0 x, 1 y, 2 z) to sigma (Pa, >= 0, compressive positive).
  void set_stress(int axis, Real sigma);
  /// Strain-rate control of an axis: rate in 1/s (compression positive; negative extends).
  void set_strain_rate(int axis, Real rate);
  Mode mode(int axis) const;
  Real goal(int axis) const;
  void set_max_speed(Real v);
  Real max_speed() const { return max_speed_; }
  void set_gain(Real g);
  Real gain() const { return gain_; }
  /// Axis-mean servo (default false: each wall on its own stress). With it both walls of a
  /// stress-controlled axis move inwards at one speed, from the axis's stress (the mean of
  /// its two walls) and their mean contact stiffness: the box cannot translate. Under gravity
  /// the bottom wall carries the grains' weight as well, so on their own stresses the bottom
  /// wall backs off while the top one pushes: once both are at the cap the box only
  /// translates and the axis's stress stays off its target for good.
  void set_symmetric(bool on) { symmetric_ = on; }
  bool symmetric() const { return symmetric_; }
  const std::vector<int>& walls() const { return walls_; }

  /// Current box dimensions, m (from the wall positions; needs a scene).
  static Vec3 box_size(const Scene& s, const std::vector<int>& walls);
  /// Stresses of the six walls, Pa (compressive positive), with the current areas.
  static std::array<Real, 6> wall_stresses(const Scene& s, const std::vector<int>& walls);
  /// Per-axis stress: mean of the two walls of the axis, Pa.
  static Vec3 axis_stresses(const Scene& s, const std::vector<int>& walls);
  /// Engineering strains (L0 - L) / L0 per axis, -, compression positive.
  Vec3 strains(const Scene& s) const;
  Vec3 reference_lengths() const { return l0_; }
  /// Takes the current box dimensions as the reference L0 (zero strain).
  void reset_strain(const Scene& s);
  /// The cap the stress-controlled walls get, m/s: max_speed, raised while an axis is
  /// strain-rate controlled to |rate| x the longest reference length, so the lateral walls
  /// can follow the deformation the loading drives (a lateral strain rate up to the axial
  /// one) instead of lagging behind at a cap set for the preparation.
  Real effective_max_speed() const;
  /// Per wall k (0..5, x-, x+, y-, y+, z-, z+; axis k / 2): calls at the cap while
  /// drifting from the target (see LimitWatch), watched while an axis is under strain-rate
  /// control (the box is loaded).
  const LimitWatch& limit(int k) const { return limit_.at(k); }
  void clear_limits() {
    for (auto& l : limit_) l.clear();
  }

  std::vector<Real> save_state() const override;
  void load_state(const std::vector<Real>& st) override;

 private:
  std::vector<int> walls_;
  Real gain_, max_speed_;
  std::array<Mode, 3> mode_{Mode::Stress, Mode::Stress, Mode::Stress};
  Vec3 goal_ = Vec3::Zero();
  Vec3 l0_ = Vec3::Zero();
  bool l0_set_ = false;
  bool symmetric_ = false;
  std::array<LimitWatch, 6> limit_{};
};

/// The walls a controller moves: a ServoWall's wall, a TriaxialController's six, a
/// CylinderServo's cylinder k as -1 - k, a MeshServo's mesh k as kMeshWallCode - k; none for
/// the others (RadiusGrowth reads the walls but
/// does not move them).
std::vector<int> controlled_walls(const Controller& c);
/// controlled_walls' code of mesh wall 0 (mesh k: kMeshWallCode - k).
constexpr int kMeshWallCode = -(1 << 24);

/// Refuses (ParameterError) a controller `c` about to be added to `s` that is in `s` already,
/// or that is enabled and moves a wall that an enabled controller of `s` moves already (the
/// two would set the wall's velocity in turn); names the wall and the first controller.
void check_new_controller(const Scene& s, const Controller& c);

/// Refuses (ParameterError) two enabled controllers of `s` that move the same wall (one may
/// have been enabled after both were added), naming both and the wall. Before a run.
void check_enabled_controllers(const Scene& s);

/// Radius growth under stress control (001 §4.3.1; the expansion of REFD, 000 §2.3): every
/// call multiplies the radii of the controlled spheres by m = 1 + gain (sigma_t - sigma) / S,
/// where sigma is the mean normal stress of the box walls (Pa) and
/// S = (1/V) sum_c k_n,c l_c^2 (Pa) the stress increase per unit radius strain predicted from
/// the current contacts (l_c the branch length: r_i + r_j for a pair, r for a sphere on a
/// wall) — an adaptive form of 001's fixed constant K. m is capped to [1 - max_strain,
/// 1 + max_strain] per call; with no contact, m = 1 + max_strain. Masses follow the radii.
///
/// grown_only (opt-in, off by default): sigma and S count only the contacts that touch a
/// growing sphere, and no bonds: the stress of the grains that grow, not of the bodies held
/// among them. In a periodic cell sigma is then the mean normal stress of those pair contacts
/// (Love–Weber, 1/V sum f . l / 3); with walls it stays the walls' stress and only S changes.
/// A reinforced cell's sheet (bonded spheres) carries tension that the grains' growth puts in
/// it (they wedge into its apertures and stretch it): counted in sigma, it offsets the target,
/// and the grains end far above it (docs/periodic.md).
class RadiusGrowth : public Controller, public StatefulController {
 public:
  /// walls: the six box walls, or none in a periodic cell (the stress is then the mean normal
  /// stress of the cell, Scene::cell_stress); bodies: ids of the spheres that grow (empty: all spheres);
  /// target_stress Pa (> 0); gain in (0, 1]; max_strain in (0, 0.1].
  RadiusGrowth(std::vector<int> walls, std::vector<int> bodies, Real target_stress, Real gain,
               Real max_strain);
  void apply(Scene& scene) override;
  void set_target_stress(Real sigma);
  Real target_stress() const { return target_; }
  /// Mean wall stress at the last call, Pa.
  Real measured_stress() const { return sigma_; }
  /// Product of all multipliers applied so far, -.
  Real total_factor() const { return total_; }
  /// Multiplier of the last call, -.
  Real last_factor() const { return last_; }
  /// Count only the contacts touching a growing sphere (see the class).
  void set_grown_only(bool on) { grown_only_ = on; }
  bool grown_only() const { return grown_only_; }
  /// Six values (the format before grown_only) while grown_only is off, seven with it.
  std::vector<Real> save_state() const override;
  void load_state(const std::vector<Real>& st) override;

 private:
  std::vector<int> walls_, bodies_;
  Real target_, gain_, max_strain_;
  Real sigma_ = 0, total_ = 1, last_ = 1;
  bool grown_only_ = false;
  std::vector<Real> radii_;  // scratch
  std::vector<char> grows_;  // scratch: per storage slot, the sphere grows
};

/// Mixed stress and strain-rate control of a periodic cell (as Yade's PeriTriaxController and
/// PFC's periodic servo): each component (r, c) of the velocity gradient L is either imposed
/// (a rate, 1/s; tension positive, as L itself) or servo-controlled so that the cell stress
/// component sigma_rc (Scene::cell_stress, Pa, compression positive) reaches a target. The
/// servo's correction per call is gain (sigma_target - sigma_rc) / C_rc of strain, C_rc the
/// affine stiffness (1/V) sum_c l_c,c^2 K_c,rr of the contact network (K_c = k_n n n +
/// k_s (I - n n)), spread over the `period` steps to the next call and capped to max_rate.
/// Without contacts a stress-controlled component moves at the cap towards its target.
/// Bonds (a sheet of bonded spheres in the cell) count in both, as in the cell stress, with
/// their springs (Bond::stiffness): a sheet in the x–y plane stiffens C_xx, C_yy and C_xy,
/// which it resists, and adds nothing to C_rz (its bonds' l_z is zero), so the servo of z is
/// the grains'.
class CellController : public Controller {
 public:
  enum class Mode : int { Rate = 0, Stress = 1 };
  /// gain in (0, 1]; max_rate: the cap on |L_rc| of servo-controlled components, 1/s (> 0).
  /// Every component starts rate-controlled at 0.
  CellController(Real gain, Real max_rate);
  void apply(Scene& scene) override;
  /// Imposes L_rc = rate (1/s; r, c in 0..2).
  void set_rate(int r, int c, Real rate);
  /// Servo-controls sigma_rc to sigma (Pa, compression positive) through L_rc. Only one of
  /// (r, c) and (c, r) may be stress-controlled: both act on the same stress. A normal
  /// component (r == c) must be >= 0: a cell of cohesionless grains cannot hold tension (the
  /// servo would stretch it without end), unless allow_tension (a cell whose bonds hold it).
  void set_stress(int r, int c, Real sigma);
  /// Tensile normal targets allowed (off by default): for a cell with a sheet of bonded
  /// spheres that carries the tension (a prestressed reinforced cell).
  void set_allow_tension(bool on) { allow_tension_ = on; }
  bool allow_tension() const { return allow_tension_; }
  Mode mode(int r, int c) const { return mode_[3 * r + c]; }
  Real goal(int r, int c) const { return goal_[3 * r + c]; }
  void set_gain(Real g);
  Real gain() const { return gain_; }
  void set_max_rate(Real v);
  Real max_rate() const { return max_rate_; }
  /// Cell stress at the last call, Pa (compression positive, not symmetrised).
  const Mat3& measured_stress() const { return sigma_; }
  /// The affine stiffness C_rc at the last call, Pa.
  const Mat3& stiffness() const { return stiff_; }
  /// Largest |sigma_rc - target| / max(|target|, 1 Pa) over the stress-controlled
  /// components at the last call, -.
  Real stress_error() const { return error_; }
  /// Per component (3 r + c): calls at the rate cap while drifting from the target.
  const std::array<LimitWatch, 9>& limits() const { return limit_; }
  void clear_limits() {
    for (auto& w : limit_) w.clear();
  }

 private:
  void check_index(int r, int c) const;
  std::array<Mode, 9> mode_{};
  std::array<Real, 9> goal_{};
  Real gain_, max_rate_;
  bool allow_tension_ = false;
  Mat3 sigma_ = Mat3::Zero(), stiff_ = Mat3::Zero();
  Real error_ = 0;
  std::array<LimitWatch, 9> limit_{};
};

}  // namespace cpp_dem
