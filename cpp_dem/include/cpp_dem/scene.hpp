// The scene: bodies (structure of arrays), walls, contacts, and the step loop.
// State is passed explicitly; there is no global scene.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "cpp_dem/bodies/body_store.hpp"
#include "cpp_dem/bodies/cell.hpp"
#include "cpp_dem/bodies/clump.hpp"
#include "cpp_dem/bodies/geogrid.hpp"
#include "cpp_dem/bodies/cylinder_wall.hpp"
#include "cpp_dem/bodies/mesh_wall.hpp"
#include "cpp_dem/bodies/wall.hpp"
#include "cpp_dem/broadphase/collider.hpp"
#include "cpp_dem/contacts/contact_record.hpp"
#include "cpp_dem/contacts/grid_contact.hpp"
#include "cpp_dem/contacts/pair_contact.hpp"
#include "cpp_dem/contacts/wall_contact.hpp"
#include "cpp_dem/laws/bond.hpp"
#include "cpp_dem/laws/material.hpp"

namespace cpp_dem {

/// Energy terms, J. The balance: kinetic + elastic + gravity_potential + dissipation
/// - work_in stays equal to its value when tracking started.
struct Energies {
  Real kinetic = 0;            ///< translational + rotational, at the start of the last step
  Real elastic = 0;            ///< stored in contact springs
  Real gravity_potential = 0;  ///< -sum m g . x, relative to where tracking started
  Real friction = 0;           ///< dissipated by Coulomb and rolling slip
  Real viscous = 0;            ///< dissipated by viscous contact damping
  Real local_damping = 0;      ///< dissipated by Cundall local damping
  Real plastic = 0;            ///< geogrid links: plastic moments and energy lost at breakage; bonds: energy released when a part breaks
  Real wall_work = 0;          ///< work done by moving walls on the bodies
  Real external_work = 0;      ///< work of external forces and of imposed (blocked) DOFs
  Real cell_work = 0;          ///< periodic cell: work of the mean field on the contacts
  Real balance_error = 0;      ///< absolute, J
  Real balance_error_relative = 0;  ///< balance_error / sum of |terms|
};

/// Summary of the broad phase, for users and tests.
struct ColliderStats {
  long builds = 0;          ///< number of broad-phase builds so far
  long pair_candidates = 0; ///< sphere–sphere candidate pairs in the current list
  /// sphere–sphere contact records: the candidates that carry history (touching, or having
  /// slipped), or every candidate where the scene has the cold part (Scene::cand_j_)
  long pair_records = 0;
  long wall_candidates = 0; ///< sphere–wall candidates in the current list
  long grid_candidates = 0; ///< grain–geogrid primitive candidates in the current list
};

class Scene;

/// The rotation update of clumps with distinct principal moments (integrate/clumps.cpp).
enum class ClumpRotation : std::uint8_t {
  Fincham = 0,  ///< Fincham's (1992) leapfrog: second order (default)
  Yade = 1,     ///< Yade 2023's variant of it, first order: for comparisons with Yade
};

/// The relative velocity at a sphere–sphere contact from which the shear spring grows
/// (geometry/sphere_sphere.hpp, docs/core.md "Yade's shear kinematics").
enum class ShearKinematics : std::uint8_t {
  /// Rigid-body velocities at the contact point, branch lengths r - overlap/2 (default).
  ContactPoint = 0,
  /// Yade's ScGeom with avoidGranularRatcheting: the translational part scaled by
  /// alpha = (r_i + r_j) / (r_i + r_j - overlap), the spins times the full radii.
  Yade = 1,
};

/// A controller (servo wall, radius growth, clamp, ...) runs every `period` steps, at the start
/// of a step, before the contact forces: it sees the forces of the previous step and touches
/// only what it owns (its walls, its bodies).
class Controller {
 public:
  virtual ~Controller() = default;
  /// Called by the scene when step_count() % period == 0.
  virtual void apply(Scene& scene) = 0;
  int period = 1;        ///< steps between calls (>= 1)
  bool enabled = true;
};

class Scene {
 public:
  Scene();

  // ---- materials, bodies, walls -------------------------------------------------------
  int add_material(const Material& m);
  const Material& material(int id) const;
  int num_materials() const { return static_cast<int>(materials_.size()); }
  /// Gives the pair of materials (a, b) its own law over the mixing rules (PairLaw); replaces
  /// an earlier law of the same pair. Contacts take it at their next step.
  void set_pair_law(int a, int b, PairLaw law);
  const std::vector<PairLaw>& pair_laws() const { return pair_laws_; }
  /// The law of materials a and b, or nullptr when they mix by the rules alone.
  const PairLaw* pair_law(int a, int b) const {
    if (pair_laws_.empty()) return nullptr;
    if (a > b) std::swap(a, b);
    for (const PairLaw& l : pair_laws_)
      if (l.a == a && l.b == b) return &l;
    return nullptr;
  }

  /// Adds spheres; returns the id of the first. pos: n centres, m; radius: n radii, m.
  int add_spheres(const std::vector<Vec3>& pos, const std::vector<Real>& radius, int material);
  int num_bodies() const { return static_cast<int>(bodies_.pos.size()); }

  // ---- geogrid (000 §2.2) ----------------------------------------------------------------
  // Without the geogrid (built with -DCPP_DEM_GEOGRID=OFF, kGeogridBuilt false) the three
  // add_* entry points throw ParameterError and the accessors return empty lists.
  /// Adds grid nodes (6-DOF bodies that are not spheres to the collider): centres (m), the
  /// node radius R_c (m), lumped masses (kg) and inertias (kg m^2). Returns the first id.
  int add_grid_nodes(const std::vector<Vec3>& pos, Real radius, const std::vector<Real>& mass,
                     const std::vector<Real>& inertia, int material);
  /// Adds a cohesive link (and connection cylinder) between nodes a and b; returns its index.
  int add_grid_link(int a, int b, const BeamParams& params, int material);
  /// Adds a PFacet on three nodes joined by the links l01, l12, l20; returns its index.
  int add_pfacet(int n0, int n1, int n2, int l01, int l12, int l20, int material);
  int num_grid_links() const { return static_cast<int>(links_.size()); }
  int num_pfacets() const { return static_cast<int>(facets_.size()); }
  const std::vector<GridLink>& grid_links() const { return links_; }
  const std::vector<PFacet>& pfacets() const { return facets_; }
  const std::vector<GridContact>& grid_contacts() const { return grid_contacts_; }
  const std::vector<BreakEvent>& break_events() const { return breaks_; }
  /// Body kind: 0 sphere, 1 grid node.
  const std::vector<std::uint8_t>& body_kinds() const { return bodies_.kind; }
  /// Grid nodes touch walls (as spheres of radius R_c) only when this is on; off by default
  /// (the pull-out box of 000 never touches the geogrid).
  bool grid_wall_contacts() const { return grid_wall_contacts_; }
  void set_grid_wall_contacts(bool on) {
    grid_wall_contacts_ = on;
    dirty_ = true;
  }
  /// Sets the masses (kg) and inertias (kg m^2) of bodies (e.g. node density scaling).
  void set_mass_inertia(int body, Real mass, Real inertia);

  // ---- clumps (bodies/clump.hpp) ----------------------------------------------------------
  /// Adds a clump: member spheres at `local` (m, in the clump's principal frame about its
  /// centre of mass) with radii `radius` (m) and one material; the clump's mass (kg),
  /// principal moments of inertia (kg m^2), centre of mass `com` (m) and orientation `ori`
  /// (principal frame -> global). The members become spheres with consecutive ids (the first
  /// is num_bodies() before the call); each carries the clump's mass times its share of the
  /// members' summed volume. Returns the clump's index.
  /// stiffness_radius (m, >= 0): the radius the members' contacts take for their stiffness
  /// (ClumpStore::stiffness_radius; 0: each member's own).
  int add_clump(const std::vector<Vec3>& local, const std::vector<Real>& radius, int material,
                Real mass, const Vec3& inertia, const Vec3& com, const Quat& ori,
                Real stiffness_radius = 0);
  int num_clumps() const { return clumps_.size(); }
  bool has_clumps() const { return !clumps_.pos.empty(); }
  /// The clumps' state (members by slot; see clump_members for ids).
  const ClumpStore& clumps() const { return clumps_; }
  /// Per body (storage order): its clump's index, -1 for a free body.
  const std::vector<int>& clumps_of_bodies() const { return bodies_.clump; }
  /// Ids of clump c's members.
  std::vector<int> clump_members(int c) const;
  /// Sets clump c's centre of mass (m), orientation, velocity (m/s) and spin (rad/s, global),
  /// and moves its members with it.
  void set_clump_state(int c, const Vec3& pos, const Quat& ori, const Vec3& vel,
                       const Vec3& angvel);
  /// Blocked DOFs of clump c (Dof mask; a blocked DOF keeps its velocity, which may be an
  /// imposed one). Blocked rotations are taken about the global axes.
  void set_clump_blocked(int c, std::uint8_t mask);
  /// Imposed force (N) and torque (N m, about the centre of mass) on clump c.
  void set_clump_external(int c, const Vec3& force, const Vec3& torque);
  ClumpRotation clump_rotation() const { return clump_rotation_; }
  void set_clump_rotation(ClumpRotation r) { clump_rotation_ = r; }

  /// Kinematics of the sphere–sphere shear spring (ShearKinematics; default ContactPoint).
  /// Only the pair pass reads it (not walls, the geogrid or bonds); it may change at any step.
  ShearKinematics shear_kinematics() const { return shear_kinematics_; }
  void set_shear_kinematics(ShearKinematics k) { shear_kinematics_ = k; }

  // ---- bonds between spheres (laws/bond.hpp, docs/bonds.md) --------------------------------
  /// Bonds spheres a and b (ids) with a linear contact and, as p asks, a contact bond and a
  /// parallel bond, formed unloaded at their present distance. The pair pass never sees a
  /// bonded pair: the bond's record is its contact for good (after both bonds broke, the
  /// plain frictional linear contact). Returns the bond's index.
  int add_bond(int a, int b, const BondParams& p);
  int num_bonds() const { return static_cast<int>(bonds_.size()); }
  /// The bonds (a, b are slots: see id_of).
  const std::vector<Bond>& bonds() const { return bonds_; }
  /// Where bond l sees its sphere b relative to b's stored position: H times the bond's
  /// image shift in a periodic cell (Bond::cell_shift), zero without one, m.
  Vec3 bond_shift(const Bond& l) const {
    if (!cell_.on) return Vec3::Zero();
    Vec3 s;
    const std::array<int, 3> ia = bodies_.image_of(l.a), ib = bodies_.image_of(l.b);
    for (int a = 0; a < 3; ++a) s[a] = l.cell_shift[a] + ib[a] - ia[a];
    return cell_.h * s;
  }
  /// Every break of a bond part so far, in the order they happened.
  const std::vector<BondBreak>& bond_breaks() const { return bond_breaks_; }

  // ---- periodic cell (bodies/cell.hpp, docs/periodic.md) ----------------------------------
  // Supported: spheres in a cell periodic along any axes, and walls normal to the axes that
  // are not periodic (with a mean field only along the periodic ones). Not yet: clumps and the
  // geogrid in a periodic cell (ParameterError).
  /// Makes the scene periodic along the axes marked in `periodic` (at least one), with cell
  /// vectors the columns of h (m, det h > 0); the cell is H [0,1)^3. Bodies are wrapped into
  /// it at the next broad-phase build. Resets the velocity gradient to zero.
  void set_periodic_cell(const Mat3& h, const std::array<bool, 3>& periodic);
  bool is_periodic() const { return cell_.on; }
  const PeriodicCell& cell() const { return cell_; }
  /// The imposed velocity gradient L (1/s): the cell deforms as dH/dt = L H and every body
  /// carries the mean velocity L x. Rows and columns of axes that are not periodic must be 0.
  void set_velocity_gradient(const Mat3& l);
  /// Whether bodies carry the mean spin axial(skew L) (default on: a rigid rotation of the
  /// cell then turns every grain with it, frame-indifferently; off: as Yade).
  void set_mean_spin(bool on);
  /// Love–Weber stress of the pair contacts over the cell volume, Pa, compression positive,
  /// not symmetrised: (1/V) sum_c f_c (x) l_c, f_c the force on j, l_c = x_j + shift - x_i.
  Mat3 cell_stress() const;
  /// The shift of pair contact k's second body (its image is x_j + shift), m; zero without
  /// a cell.
  Vec3 pair_shift(size_t k) const {
    const std::uint8_t image = candidate_image(k);
    if (image == kNoShift) return Vec3::Zero();
    Vec3 s;
    for (int a = 0; a < 3; ++a) s[a] = image_shift(image, a);
    return cell_.h * s;
  }
  /// Per body (storage order): the cell vectors it was shifted by when wrapped (its
  /// unwrapped position is pos + H image).
  std::vector<std::array<int, 3>> body_images() const {
    return bodies_.image.empty() ? std::vector<std::array<int, 3>>(bodies_.size(), {0, 0, 0})
                                 : bodies_.image;
  }

  int add_wall(int axis, Real position, int sense, int material);
  /// Opens wall `id` for bodies whose centre lies in (lo, hi) along `axis` (WallOpening);
  /// axis = -1 closes it again.
  void set_wall_opening(int id, int axis, Real lo, Real hi);
  const WallOpening& wall_opening(int id) const;
  int num_walls() const { return static_cast<int>(walls_.size()); }
  Wall& wall(int id);
  const Wall& wall(int id) const;
  /// Adds a cylindrical wall (CylinderWall; passes/cylinder_wall.cpp): axis through `centre`
  /// along `axis` (normalised here), radius (m), spheres inside (inside = true) or outside
  /// it, its lateral surface between lo and hi (m along the axis from centre; +-inf: an
  /// infinite cylinder). Not in a periodic cell. Returns its index.
  int add_cylinder_wall(const Vec3& centre, const Vec3& axis, Real radius, bool inside,
                        int material, Real lo, Real hi);
  int num_cylinder_walls() const { return static_cast<int>(cylinder_walls_.size()); }
  CylinderWall& cylinder_wall(int id);
  const CylinderWall& cylinder_wall(int id) const;
  /// Sets cylinder `id`'s radius (m): the move counts towards the next broad-phase build.
  void set_cylinder_radius(int id, Real radius);
  const std::vector<WallContact>& cylinder_contacts() const { return cylinder_contacts_; }
  /// Adds a rigid triangle-mesh wall (MeshWall; passes/mesh_wall.cpp): vertices (m) and
  /// triangles (indices into them). Its moment is taken about the vertices' mean. Not in a
  /// periodic cell. Returns its index.
  int add_mesh_wall(const std::vector<Vec3>& vertices,
                    const std::vector<std::array<int, 3>>& triangles, int material);
  int num_mesh_walls() const { return static_cast<int>(mesh_walls_.size()); }
  MeshWall& mesh_wall(int id);
  const MeshWall& mesh_wall(int id) const;
  /// Every mesh's triangles (MeshWall::tri_off, ntri), indices into its own vertices.
  const std::vector<std::array<int, 3>>& mesh_triangles() const { return mesh_tris_; }
  /// The current vertices of mesh `id`, m.
  std::vector<Vec3> mesh_vertices(int id) const;
  /// Sphere–mesh contacts beyond MeshContact::kMaxSubs at one step, left out (the deepest
  /// kept), since the scene was made.
  long mesh_dropped_contacts() const { return mesh_dropped_; }

  // ---- storage order ------------------------------------------------------------------
  // At its first broad-phase build (while no contact exists yet) the scene stores its
  // spheres in a spatial order (Morton order of cells one mean diameter wide), so that bodies
  // near in space are near in memory; grid nodes keep their places. Ids do not change: the
  // per-body arrays below and the body indices in contact records (PairContact::i/j,
  // WallContact::body, GridContact::sphere) are in storage order ("slots"); the methods that
  // take one body (set_blocked, set_mass_inertia, set_body_material, add_grid_link,
  // add_pfacet) take its id, and errors name ids. The Python face speaks ids only.
  /// Id of the body stored at slot s.
  int id_of(int slot) const { return id_of_slot_.empty() ? slot : id_of_slot_[slot]; }
  /// Slot where body `id` is stored.
  int slot_of(int id) const { return slot_of_id_.empty() ? id : slot_of_id_[id]; }
  /// The bodies are stored in id order (no spatial sort happened, or it was switched off).
  bool identity_order() const { return id_of_slot_.empty(); }
  /// A per-body array in storage order, copied into id order.
  template <class T>
  std::vector<T> by_id(const std::vector<T>& a) const {
    if (id_of_slot_.empty()) return a;
    std::vector<T> out(a.size());
    for (size_t s = 0; s < a.size(); ++s) out[id_of_slot_[s]] = a[s];
    return out;
  }
  /// A per-body array in id order, copied into storage order.
  template <class T>
  std::vector<T> by_slot(const std::vector<T>& a) const {
    if (id_of_slot_.empty() || a.size() != id_of_slot_.size()) return a;  // size checked later
    std::vector<T> out(a.size());
    for (size_t s = 0; s < a.size(); ++s) out[s] = a[id_of_slot_[s]];
    return out;
  }
  /// Sort the spheres spatially at the first broad-phase build (default on). Off keeps the
  /// storage order equal to the id order. Has no effect once the scene has contacts.
  bool spatial_sort() const { return spatial_sort_; }
  void set_spatial_sort(bool on) { spatial_sort_ = on; }

  // ---- state arrays (SI, storage order) --------------------------------------------------
  const std::vector<Vec3>& positions() const { return bodies_.pos; }
  const std::vector<Vec3>& velocities() const { return bodies_.vel; }
  const std::vector<Vec3>& angular_velocities() const { return bodies_.angvel; }
  const std::vector<Vec3>& forces() const { return bodies_.force; }
  const std::vector<Vec3>& torques() const { return bodies_.torque; }
  const std::vector<Real>& radii() const { return bodies_.radius; }
  const std::vector<Real>& masses() const { return bodies_.mass; }
  const std::vector<Real>& inertias() const { return bodies_.inertia; }
  const std::vector<Quat>& orientations() const { return bodies_.ori; }
  const std::vector<int>& body_materials() const { return bodies_.material; }
  const std::vector<std::uint8_t>& blocked() const { return bodies_.blocked; }
  /// By slot, N and N m (zeros where none was ever set: the arrays are allocated then).
  std::vector<Vec3> external_forces() const {
    return bodies_.ext_force.empty() ? std::vector<Vec3>(bodies_.pos.size(), Vec3::Zero()) : bodies_.ext_force;
  }
  std::vector<Vec3> external_torques() const {
    return bodies_.ext_torque.empty() ? std::vector<Vec3>(bodies_.pos.size(), Vec3::Zero()) : bodies_.ext_torque;
  }

  // Setters of whole arrays take storage order (the bindings translate from id order).
  void set_positions(const std::vector<Vec3>& v);
  void set_velocities(const std::vector<Vec3>& v);
  void set_angular_velocities(const std::vector<Vec3>& v);
  /// Sets radii (m) and rescales the spheres' mass and inertia with their material density.
  /// Grid nodes keep their lumped mass and must keep their radius (R_c).
  void set_radii(const std::vector<Real>& r);
  void set_blocked(int body, std::uint8_t mask);
  void set_external_forces(const std::vector<Vec3>& f);
  void set_external_torques(const std::vector<Vec3>& t);
  void set_body_material(int body, int material);
  /// One body's velocity (m/s) and external force (N), by id: what a controller that owns
  /// bodies (MembranePressure, PlatenClamp) sets every step. The id is checked.
  void set_body_velocity(int body, const Vec3& v);
  void set_body_external_force(int body, const Vec3& f);
  /// Writes one component of a body's velocity, spin, external force or torque without the
  /// setters' checks (a non-finite value, as a law or controller could produce one): the
  /// blow-up detector's tests. field: "velocities", "angular_velocities", "external_forces"
  /// or "external_torques".
  void inject_unchecked(const std::string& field, int body, int axis, Real value);

  // ---- parameters ----------------------------------------------------------------------
  Real dt() const { return dt_; }
  void set_dt(Real dt);
  const Vec3& gravity() const { return gravity_; }
  void set_gravity(const Vec3& g);
  Real local_damping() const { return local_damping_; }
  void set_local_damping(Real d);
  /// Verlet margin of the broad phase, m, >= 0; 0 means 0.2 x the mean radius (default).
  Real verlet_margin() const { return margin_; }
  void set_verlet_margin(Real m);
  Real max_overlap_ratio() const { return max_overlap_ratio_; }
  /// Overlap / smaller radius beyond which a step raises BlowUpError.
  void set_max_overlap_ratio(Real r);
  /// Largest distance a body may move in one step, as a fraction of its radius, -: beyond it
  /// the step raises BlowUpError (tunnelling). Default 1: a grain that moves at most its
  /// radius per step cannot cross a wall, a grain or a geogrid member without one step in an
  /// overlap deeper than max_overlap_ratio = 0.5 of its radius (the band of such overlaps
  /// along any path through them is at least one radius long), which the overlap check
  /// names; a grain that moves farther can pass through without ever overlapping.
  Real max_step_ratio() const { return max_step_ratio_; }
  void set_max_step_ratio(Real r);
  bool track_energy() const { return track_energy_; }
  void set_track_energy(bool on);
  /// Automatic time step: dt = safety x critical_dt() now and, with period > 0, again every
  /// `period` steps; period 0 sets it once (it is not updated during the run).
  void set_auto_timestep(Real safety, int period);
  Real timestep_safety() const { return ts_safety_; }
  int timestep_period() const { return ts_period_; }
  /// Density scaling for quasi-static stages (off by default). Sets dt = target_dt (s) and,
  /// now and every `period` steps, gives each free body and each clump the inertia factor
  /// s = max(1, (target_dt / (safety x its own critical step))^2), its critical step taken
  /// from the stiffness of its active contacts, bonds and links (sqrt(2 m / K) per axis, as
  /// critical_dt, without the stiffness floor of a grain with no contact), updated just
  /// before the bodies move (a contact formed in the step counts at once). A factor falls
  /// at most by half per update; a body that never touched keeps s = 1. Weight and gravity
  /// stay the true ones (mass x g). Velocities are
  /// kept when a factor changes (a clump's angular momentum follows its spin). While it is
  /// on, the automatic time step is not applied, and critical_dt and the dt check take the
  /// scaled inertia. safety in (0, 1], period >= 1.
  void set_density_scaling(Real target_dt, Real safety, int period);
  /// Switches density scaling off: every factor back to 1 (velocities kept).
  void clear_density_scaling();
  bool density_scaling() const { return ds_on_; }
  Real density_scaling_target_dt() const { return ds_target_dt_; }
  Real density_scaling_safety() const { return ds_safety_; }
  int density_scaling_period() const { return ds_period_; }
  /// What density scaling does now (all from the current factors and state).
  struct DensityScalingStats {
    Real max_factor = 1;        ///< largest inertia factor, -
    Real mean_factor = 1;       ///< mass-weighted mean factor of the free bodies and clumps, -
    Real scaled_share = 0;      ///< share of free bodies and clumps with a factor above 1, -
    int scaled = 0;             ///< how many, -
    int movable = 0;            ///< free (not fully blocked) bodies and clumps, -
    /// The sample's inertial number with the scaled inertia, -: sqrt(sum_c rho_c |dv_c|^2 /
    /// sum_c (|f_c| / d_c^2)) over the active pair contacts, dv_c the relative velocity of
    /// the two centres (the image's in a periodic cell), f_c the contact force, d_c the sum
    /// of the radii and rho_c the two bodies' mean density times their factor: gamma_dot d /
    /// sqrt(p / rho) with gamma_dot d the neighbours' relative speed and p ~ f / d^2. 0
    /// when no pair contact carries a force.
    Real inertial_number = 0;
  };
  DensityScalingStats density_scaling_stats() const;
  /// The inertia factor of a body (its clump's for a clump member), -.
  Real inertia_scale(int id) const;

  // ---- controllers ---------------------------------------------------------------------
  /// Adds a controller; returns its index. Controllers run in the order they were added.
  int add_controller(std::shared_ptr<Controller> c);
  int num_controllers() const { return static_cast<int>(controllers_.size()); }
  /// Removes every controller (e.g. a preparation's, before the scene is used on).
  void clear_controllers() { controllers_.clear(); }
  std::shared_ptr<Controller> controller(int id) const;

  // ---- running -------------------------------------------------------------------------
  /// Runs n steps in C++. With `interrupted`, asks it about every 0.1 s of wall time
  /// (between steps, never inside one) whether to stop; returns the steps done, n unless it
  /// said yes.
  long run(long n, const std::function<bool()>& interrupted = {});
  long step_count() const { return step_; }
  Real time() const { return time_; }

  // ---- estimates and measurements ------------------------------------------------------
  /// Critical time step estimate, s, from the current contact stiffnesses
  /// (min over bodies and axes of sqrt(2 m / K_axis), translational and rotational); the
  /// p-wave estimate when no contact is active.
  Real critical_dt() const;
  /// critical_dt() and the body that sets it (-1 when no contact or link exists). With
  /// `contact_seen`, the estimate a contact anywhere gives (every grain's stiffness floor)
  /// even when none is active now.
  Real critical_dt_body(int* body, bool contact_seen = false) const;
  /// Every `period` steps (0 = off) a run without the automatic time step checks that dt does
  /// not exceed the critical estimate of the contacts active now and of every contact that
  /// formed since the last check (check_dt), and throws BlowUpError naming the step, dt, the
  /// estimate and the body if it does.
  void set_dt_check_period(int period);
  int dt_check_period() const { return dt_check_period_; }
  /// p-wave estimate min_b R_b sqrt(rho_b / E_b), s.
  Real pwave_dt() const;
  Energies energies() const;
  /// Restarts the energy balance from the current state.
  void reset_energy();
  /// Mean |resultant force| on free bodies / mean |contact force|, - (Yade's unbalancedForce).
  Real unbalanced_force() const;
  /// Bytes allocated by each of the scene's arrays (capacity x element size), by field name
  /// ("bodies.pos", "contacts.pairs", ...): the core's own memory, not the allocator's or
  /// Python's. A vector of vectors counts its buffers too.
  std::vector<std::pair<std::string, std::size_t>> memory_by_field() const;
  ColliderStats collider_stats() const;
  /// The pair contacts the last pair pass ran eight at a time (docs/core.md, "Eight contacts
  /// at a time"), for tests: the others took the per-contact loop. It depends on the threads
  /// (a threaded pass runs its cross pairs apart), the results do not.
  long pair_batched() const { return pair_batched_; }

  /// Pair contact k is the k-th candidate pair of the last build, in (i, j) order; one that
  /// carries no history has no record (cand_j_) and is an inactive contact with zero
  /// springs (a fresh record's values).
  /// Candidate pair k's second body.
  int cand_second(size_t k) const {
    const int v = cand_j_[k];
    return v >= 0 ? pairs_[v].j : ~v;
  }
  /// Candidate pair k's record in pairs_, or -1.
  int cand_slot(size_t k) const { return cand_j_[k] >= 0 ? cand_j_[k] : -1; }
  /// Parameters of pair contact k (as of its last activation or change of materials): its
  /// cold part's, or, in a scene without one (only short kernels: ensure_pair_cold), the
  /// hot record's model, kn, ks and tan_phi, with no dashpots and no rolling resistance
  /// (mass_eff and rolling_cap, which such a contact does not read, are zero).
  ContactPhys pair_phys(size_t k) const {
    if (pair_cold_on_) return pair_cold_[k].phys;  // (with the cold part: a record each)
    ContactPhys p;
    p.model = static_cast<ContactModel>(0);  // (a fresh record's)
    const int s = cand_slot(k);
    if (s < 0) return p;
    const PairContact& c = pairs_[s];
    p.model = static_cast<ContactModel>(c.model);
    p.kn = c.kn;
    p.ks = c.ks;
    p.tan_phi = c.tan_phi;
    return p;
  }
  /// History of pair contact k, assembled from its hot record, its friction dissipation and
  /// its cold part (zero rolling moment and viscous dissipation without one).
  ContactState pair_state(size_t k) const {
    const int s = cand_slot(k);
    return s >= 0 ? record_state(s) : ContactState();
  }
  /// Whether the scene keeps the pair contacts' cold part (PairContactCold): from the first
  /// time one of its material pairs takes a kernel that reads it (ensure_pair_cold) on.
  bool pair_cold_on() const { return pair_cold_on_; }
  /// Force on body j of pair contact k, N (zero when inactive): the pair pass's output, or,
  /// after a pass that summed the forces into the bodies directly (pair_direct_: only
  /// short kernels, whose force is f_n n + f_s), that sum from the hot record, the same bits.
  Vec3 pair_force(size_t k) const {
    if (!pair_out_.empty() && pair_out_.size() == cand_j_.size())
      return pair_out_[pair_jslot_[k]].force;
    const int s = cand_slot(k);
    if (s < 0) return Vec3::Zero();
    const PairContact& c = pairs_[s];
    return Vec3(c.fn * c.normal + c.fs);
  }
  const std::vector<WallContact>& wall_contacts() const { return wall_contacts_; }
  int num_active_contacts() const;
  /// Calls f(const ContactRecord&) for every contact of every container, active or not, in a
  /// fixed order (pair, wall, grain–geogrid, cylinder, then mesh contacts, each in container
  /// order): the one
  /// walk of the contact containers for measurements, stiffness and output.
  template <class F>
  void for_each_contact(F&& f) const;
  /// for_each_contact over one container only (ContactKind::Pair, Wall, Grid, Cylinder, Mesh).
  template <class F>
  void for_each_contact_of(ContactKind kind, F&& f) const;

 private:
  friend class Checkpoint;  // exact save/restore of the whole state (checkpoint.cpp)
  void check_body(int b) const;
  /// A contact leaves the lists: its dissipation moves to the scene's totals.
  void drop_dissipation(const ContactState& s) {
    dropped_friction_ += s.dissip_friction;
    dropped_viscous_ += s.dissip_viscous;
  }
  /// History of pair record s (pairs_, its friction dissipation and cold part).
  ContactState record_state(size_t s) const {
    ContactState st;
    const PairContact& c = pairs_[s];
    st.fs = c.fs;
    if (pair_cold_on_) st.mr = pair_cold_[s].mr;
    st.normal = c.normal;
    st.overlap = c.overlap;
    st.fn = c.fn;
    st.dissip_friction = pair_dissip_[s];
    if (pair_cold_on_) st.dissip_viscous = pair_cold_[s].dissip_viscous;
    return st;
  }
  /// Pair contact record k (pairs_) leaves the lists (its dissipation to the scene's totals).
  void drop_pair_dissipation(size_t k) {
    dropped_friction_ += pair_dissip_[k];
    dropped_viscous_ += pair_cold_on_ ? pair_cold_[k].dissip_viscous : 0.0;
  }
  /// Makes the pair contacts' cold part where a material pair of the scene takes a kernel
  /// that reads it (the Hertz–Mindlin law with dashpots, the composed law: pair_kernel of
  /// each pair of materials, or rolling resistance asked by both factors), checked again
  /// when the materials change (phys_version_). Once made it stays.
  void ensure_pair_cold();
  /// The slots of the pair pass's outputs, grouped by j (pair_jadj_off_, pair_jslot_ of the
  /// comment below), from the candidate pairs and the body count of the last build
  /// (pair_ioff_).
  void index_pair_outputs(std::vector<int>& jadj_off, std::vector<int>& jslot) const;
  /// Whether the pair pass sums into the bodies directly (pair_direct_): without the cold
  /// part (on any number of threads: pair_cross_).
  bool pair_pass_direct() const;
  /// The cross pairs of a direct pass on nt threads (pair_cross_k_ and the rest, below).
  void index_pair_cross(int nt);
  /// Frees the cross pairs' index (after each build: it is made again for the next pass).
  void release_pair_cross();
  /// Adds to thread t's bodies' sums (pair_cross_b_) their shares of the cross pairs, in
  /// contact order (between start_pair_sums and the thread's rows).
  void add_cross_shares(long t);
  /// The bodies [b0, b1)'s force and torque set to where the direct pass's sums start: the
  /// external force and the weight, the external torque.
  void start_pair_sums(int b0, int b1);
  /// Frees what only a pass that keeps its outputs uses: pair_out_, its slots
  /// (pair_jadj_off_, pair_jslot_) and the first bodies' sums (pair_fi_, pair_ti_).
  void release_pair_outputs();
  /// Sets the candidate rows (cand_off_, cand_j_, for n bodies) from a list of pairs sorted
  /// by (i, j): candidate_pairs()'s inverse.
  void set_candidate_rows(const std::vector<std::pair<int, int>>& pairs, int n);
  /// Energy stored in active contacts and unbroken geogrid links, J.
  Real stored_elastic_energy() const;
  /// Appends one body (kind 0 sphere, 1 grid node) at rest to every per-body array.
  void push_body(const Vec3& x, Real radius, Real mass, Real inertia, int material,
                 std::uint8_t kind);
  bool need_rebuild() const;
  // Periodic cell (integrate/cell.cpp, broadphase/periodic.cpp).
  /// The image offsets H s of the 27 image codes, for this step's pair pass.
  void refresh_image_offsets();
  /// The mean field's map of this step for the integration pass (which applies it to each
  /// body); advance_cell then moves the cell itself.
  MeanFieldStep mean_field_step() const;
  /// After the integration: the cell takes the step's map, H -> A H.
  void advance_cell();
  /// Wraps bodies into the cell along its periodic axes (at a build).
  void wrap_into_cell();
  /// sum_c f_c (x) l_c over the active pair contacts and the bonds, N m (the cell stress
  /// times V).
  Mat3 pair_stress_sum() const;
  /// How far body `slot` has moved (m) since the last broad-phase build, plus any growth of
  /// its radius: the Verlet margin's measure (need_rebuild, the integration and clump passes).
  __attribute__((always_inline)) inline Real displacement_since_build(int slot) const {
    return displacement_since_build(slot, bodies_.pos[slot]);
  }
  /// The same for body `slot` at `pos` (m), its position in registers (the clump pass).
  __attribute__((always_inline)) inline Real displacement_since_build(int slot,
                                                                       const Vec3& pos) const {
    return (pos - pos_at_build_[slot]).norm() + radius_growth_since_build(slot);
  }
  /// How much body `slot`'s radius has grown since the last build, m (+0 where it has not).
  /// (radius_at_build_ is empty while no radius has changed since the build: +0.)
  __attribute__((always_inline)) inline Real radius_growth_since_build(int slot) const {
    if (radius_at_build_.empty()) return 0.0;
    return std::max(0.0, bodies_.radius[slot] - radius_at_build_[slot]);
  }
  /// The same in a deforming periodic cell: beyond the cell's own deformation since the build
  /// fb (= H H_build^-1), |x - fb x_build| plus any growth.
  __attribute__((always_inline)) inline Real displacement_since_build(int slot,
                                                                       const Mat3& fb) const {
    return (bodies_.pos[slot] - fb * pos_at_build_[slot]).norm() + radius_growth_since_build(slot);
  }
  void rebuild();
  /// Stores the spheres in spatial order (see "storage order"); only while no contact exists.
  void sort_bodies_spatially();
  /// Room in the per-body arrays for count more bodies (add_spheres).
  void reserve_bodies(std::size_t count);
  // The three hot passes. Each is a plain entry point (called by step(), in scene.cpp) and
  // its multiversioned body (CPP_DEM_HOT), which only its own unit calls: GCC emits the
  // clones of a target_clones function as local symbols of the unit that defines it.
  void compute_pair_forces(long& err_contact);
  // kYadeShear: ShearKinematics::Yade. One function per kinematics, so the default's code is
  // what it was before the option existed.
  template <bool kYadeShear>
  CPP_DEM_HOT void compute_pair_forces_hot(long& err_contact);
  // The pair pass without AVX2 (scene.cpp, pair_bodies_narrow) and its threads' bodies.
  void compute_pair_forces_narrow(long& err_contact);
  // kYadeShear: ShearKinematics::Yade (chosen once per pass, not per contact).
  // mode: kPassOutputs, kPassDirect (pair_cross_ shares for j >= jlimit, from slot cursor
  // on) or kPassCross (r0, r1: cross slots, their shares into pair_cross_).
  template <bool kYadeShear>
  void pair_bodies_narrow(int r0, int r1, long& err, int mode, int jlimit, long cursor);
  std::pair<int, int> pair_bodies_of_thread(long t, long nt) const;
  // The pair pass's cold paths (both forms): a contact opened; a law without short kernel.
  void open_pair(long k, PairOutput* o);
  std::pair<Vec3, Vec3> general_pair(long k, PairOutput& o, const Vec3& n, Real overlap, Real li,
                                     Real lj, const Vec3& rel_vel, const Vec3& angvel_sum,
                                     const Vec3& rel_angvel);
  void compute_wall_forces(long& err_contact);
  CPP_DEM_HOT void compute_wall_forces_hot(long& err_contact);
  // Cylindrical walls (passes/cylinder_wall.cpp): the contact pass, its candidates at a
  // build, the walls' motion and work after the integration.
  void compute_cylinder_forces(long& err_contact);
  void rebuild_cylinder_contacts(Real margin);
  void move_cylinder_walls();
  void update_phys(WallContact& c, const CylinderWall& w) const;
  // Triangle-mesh walls (passes/mesh_wall.cpp).
  void compute_mesh_forces(long& err_contact);
  void rebuild_mesh_contacts(Real margin);
  void move_mesh_walls();
  [[noreturn]] void raise_mesh_overlap(long k) const;
  [[noreturn]] void raise_cylinder_overlap(long k) const;
  void reduce_and_integrate(long& err_body);
  CPP_DEM_HOT void reduce_and_integrate_hot(long& err_body);
  /// The clump pass (after reduce_and_integrate, only with clumps): member forces into the
  /// clumps, the clumps' leapfrog, the members' state from their clump (integrate/clumps.cpp).
  void integrate_clumps(long& err_clump);
  CPP_DEM_HOT void integrate_clumps_hot(long& err_clump);
  /// Members of clump c at their clump's pose: positions, velocities, spins, orientations.
  void place_members(int c);
  void check_clump(int c) const;
  /// Pair contact c's (first body i) parameters for the current materials (into its cold
  /// part k where the scene has one), copied into its hot record.
  void update_phys(PairContact& c, size_t k, int i);
  /// The first body of candidate pair k (its row in pair_ioff_).
  int pair_first_body(long k) const {
    return static_cast<int>(std::upper_bound(pair_ioff_.begin(), pair_ioff_.end(), k) -
                            pair_ioff_.begin()) - 1;
  }
  /// A new record (c, its friction dissipation) for candidate k, found touching on thread t
  /// (pair_new_; apart from the pass's loop: rare).
  void keep_new_pair(long t, int k, const PairContact& c, Real dissip);
  /// Joins the pass's new records into pairs_, in candidate order (cand_j_).
  void adopt_new_pairs();
  /// A record for every candidate, at its candidate's index (the scene takes the cold part).
  void materialize_pairs();
  /// The records from a checkpoint's (one for every candidate, in candidate order, with
  /// pair_dissip_ the same), keeping only those that carry history: active, some friction
  /// dissipated, or the scene has the cold part. Sets cand_j_'s slots and
  /// pair_phys_version_.
  void compact_pairs(const std::vector<PairContactDisk>& disk);
  /// Whether a record (active or not, with friction dissipation d) carries history to keep
  /// at a build.
  bool pair_keeps_record(bool active, Real d) const { return pair_cold_on_ || active || d != 0; }
  /// The image code of candidate pair k (kNoShift without a cell).
  std::uint8_t candidate_image(size_t k) const {
    return candidate_images_.empty() ? kNoShift : candidate_images_[k];
  }
  /// Every candidate's record in candidate order (a fresh one where it has none, or where
  /// its record carries no history) and its friction dissipation: a checkpoint's form.
  void expanded_pairs(std::vector<PairContactDisk>& out, std::vector<Real>& dissip) const;
  /// The radius body `slot` takes in the mixing rules: its own, or its clump's stiffness radius.
  Real stiffness_radius(int slot) const {
    if (!has_clumps()) return bodies_.radius[slot];
    const int c = bodies_.clump[slot];
    return c >= 0 && clumps_.stiffness_radius[c] > 0 ? clumps_.stiffness_radius[c]
                                                      : bodies_.radius[slot];
  }
  /// Pair contact k with the full composed law (apply_law) on geometry g; returns the force
  /// on j and the extra moment, as apply_law.
  LawOutput apply_pair_law(size_t k, const ContactGeometry& g, Real dt);
  void update_phys(WallContact& c) const;
  void update_phys(GridContact& c) const;
  /// The scene has geogrid bodies or links; a compile-time false without the geogrid
  /// (kGeogridBuilt). Callers guard the geogrid calls with `if constexpr (kGeogridBuilt)` so
  /// a build without grid.cpp never references them.
  bool has_grid() const { return kGeogridBuilt && (!links_.empty() || num_nodes_ > 0); }
  void rebuild_grid_contacts(Real margin);
  /// Distance from x to a node (nn 1), a link axis (nn 2) or a triangle (nn 3), m.
  Real skeleton_distance(const int* nodes, int nn, const Vec3& x) const;
  void rebuild_grid_adjacency();
  void compute_grid_contacts(long& err_contact);
  /// grid_hot_ and grid_live_ from grid_contacts_ (after a rebuild or a checkpoint load).
  void index_grid_contacts();
  /// mesh_flat_ from the mesh contacts' candidates (after a build or a checkpoint load).
  void index_mesh_contacts();
  /// Appends the normals of triangles [t0, mesh_tris_.size()) to mesh_tri_n_ / mesh_tri_e_
  /// (from the vertices now), after truncating them to t0 entries.
  void frame_mesh_triangles(size_t t0);
  void compute_links();
  // Its multiversioned body (CPP_DEM_HOT, as the hot passes above): every intact link's step.
  CPP_DEM_HOT void compute_links_hot();
  // Bonds (passes/bonds.cpp).
  void compute_bonds(long& err);
  // Its multiversioned body (CPP_DEM_HOT, as the hot passes above): every bond's step.
  CPP_DEM_HOT void compute_bonds_hot(long& err);
  void rebuild_bond_adjacency();
  /// The spatial sort moved bodies: bonds follow (perm[new slot] = old slot).
  void remap_bonds(const std::vector<int>& perm);
  /// Removes bonded pairs from the broad phase's candidates.
  void drop_bonded_candidates();
  /// Removes the candidate pairs (i, j) for which drop(i, j) is true (called in (i, j)
  /// order), with their images.
  template <class Drop>
  void drop_candidates(Drop&& drop) {
    const int n = static_cast<int>(cand_off_.size()) - 1;
    if (n < 0) return;
    const bool images = !candidate_images_.empty();
    int out = 0, q0 = cand_off_[0];
    for (int i = 0; i < n; ++i) {
      const int q1 = cand_off_[i + 1];
      cand_off_[i] = out;
      for (int q = q0; q < q1; ++q) {
        if (drop(i, cand_j_[q])) continue;
        cand_j_[out] = cand_j_[q];
        if (images) candidate_images_[out] = candidate_images_[q];
        ++out;
      }
      q0 = q1;
    }
    cand_off_[n] = out;
    cand_j_.resize(out);
    if (images) candidate_images_.resize(out);
  }
  /// The candidate pairs as a list of (i, j) (a checkpoint's form).
  std::vector<std::pair<int, int>> candidate_pairs() const;
  [[noreturn]] void raise_bond_overlap(long k) const;
  bool has_bonds() const { return !bonds_.empty(); }
  void step();
  void set_energy_reference();
  void raise_overlap(long contact, bool wall) const;
  /// 0.2 times the mean radius, m (the broad phase's margin when none is set). Kept from its
  /// last sum until the radii change (set_radii) or the bodies are built again (rebuild):
  /// need_rebuild asks for it every step.
  Real default_margin() const;
  mutable Real default_margin_ = -1;  ///< the kept sum's margin, m (-1: to be summed)

  std::vector<Material> materials_;
  std::vector<PairLaw> pair_laws_;
  // Bodies (structure of arrays, storage order).
  BodyStore bodies_;
  ClumpStore clumps_;
  // Storage order: id of the body at each slot and its inverse (both empty: identity).
  std::vector<int> id_of_slot_, slot_of_id_;
  bool spatial_sort_ = true;
  std::vector<Vec3> pos_at_build_;
  // The radii at the last build, kept only once one has changed since it (set_radii);
  // empty otherwise (radius_growth_since_build: +0).
  std::vector<Real> radius_at_build_;
  Real max_radius_at_build_ = 0;  // largest radius at the last build, m (need_rebuild)
  std::vector<Wall> walls_;
  std::vector<WallOpening> wall_openings_;  // one per wall (axis -1: closed)
  PeriodicCell cell_;
  // Scratch of the periodic pair pass: H s for each image code, 4 doubles each (lane 3 zero).
  std::array<std::array<Real, 4>, 27> image_offset_{};
  // Image code of each candidate pair (cand_j_) in a periodic cell; empty without one (every
  // pair sees j itself, kNoShift).
  std::vector<std::uint8_t> candidate_images_;
  std::vector<std::shared_ptr<Controller>> controllers_;
  // Contacts and their adjacency (CSR: for body b, entries adj_off[b]..adj_off[b+1]).
  // Pair contacts: a record (PairContact) only for the candidate pairs that carry history.
  // Candidate k (in row i: pair_ioff_[i] <= k < pair_ioff_[i + 1]) has record cand_j_[k] in
  // pairs_ (which holds its second body), or, where cand_j_[k] < 0, none (its second body is
  // ~cand_j_[k]; cand_second, cand_slot): a candidate that has not touched since the last build
  // (or touched and opened without slipping) is nothing but its candidate entry, and takes
  // a record the step it touches (pair_new_, adopt_new_pairs: after those of the build). At a
  // build the records that carry history (active, or some friction dissipated) are kept, in
  // candidate order.
  // A scene with the cold part (pair_cold_on_) keeps a record for every candidate, each at
  // its candidate's index (cand_j_[k] == k), as pair_out_ and pair_jslot_ assume.
  // pair_dissip_ and pair_cold_ go with the records.
  std::vector<PairContact> pairs_;
  // The scene phys version (phys_version_) of the last pair pass: every active record's
  // parameters are those of its materials then; the next pass makes them again where the
  // materials have changed since.
  int pair_phys_version_ = -1;
  // A candidate the pair pass found touching without a record: its new record, made on
  // the thread that computed it (pair_new_[t]), joined into pairs_ after the pass in
  // candidate order (adopt_new_pairs).
  struct NewPair {
    int k;
    Real dissip;
    PairContact c;
  };
  std::vector<std::vector<NewPair>> pair_new_;
  std::vector<PairContactCold> pair_cold_;  // empty unless pair_cold_on_ (ensure_pair_cold)
  bool pair_cold_on_ = false;
  int pair_cold_version_ = -1;  // phys_version_ at the last ensure_pair_cold
  int pair_cold_missing_ = 0;   // set by update_phys if a kernel needs the cold part (a bug)
  // Friction dissipated by each pair contact, J (ContactState::dissip_friction).
  std::vector<Real> pair_dissip_;
  std::vector<PairOutput> pair_out_;  // empty after a direct pass (pair_direct_)
  // The last pair pass ran with short kernels only (no cold part) and summed each
  // contact's force and torque into its bodies' force and torque at once (which it started
  // from the body's external force and weight), in the order the reduction sums pair_out_:
  // the reduction then reads those sums, and pair_out_ is not kept (on more threads as on
  // one: pair_cross_, below).
  bool pair_direct_ = false;
  // The pair passes left to run without the batch of active linear contacts (pair.cpp's
  // kBatchRest; a speed choice only: both loops give the same bits).
  int pair_batch_rest_ = 0;
  long pair_batched_ = 0;  // (the contacts the last pass's batch ran: pair_batched())
  // Per body: the sum over its contacts as i of -force and torque_i, written by the pair
  // pass every step (scratch, not state).
  // i's share of its pair contacts' forces (N) and torques (N m), 4 doubles per body (the
  // fourth zero), so they are stored and loaded as one register.
  std::vector<std::array<Real, 4>> pair_fi_, pair_ti_;
  // A direct pass on nt > 1 threads (index_pair_cross, made for pair_cross_nt_ threads at the
  // first pass after a build): thread t sums bodies [b0, b1) (pair_cross_b_, below), and the
  // contacts of its rows whose j is >= b1 (cross pairs: the tails of the rows, whose j
  // another thread sums) are pair_cross_k_[pair_cross_t_[t] .. pair_cross_t_[t + 1]), in
  // contact order. Their shares (pair_cross_) are computed first, the threads taking equal
  // parts of them; then each thread starts its bodies' sums, adds the cross shares whose j
  // it sums (pair_cross_j_: slots by (j, slot), thread t's from pair_cross_jt_[t]), and runs
  // its rows, adding each cross pair's share of i in its place: every sum in the one-thread
  // pass's order, so the bits do not depend on the threads.
  // The threads' bodies are pair_cross_b_[t] .. pair_cross_b_[t + 1], split so that the
  // contacts each computes in its rows, besides its part of the cross pairs, are equal.
  std::vector<int> pair_cross_k_, pair_cross_t_, pair_cross_j_, pair_cross_jt_, pair_cross_b_;
  std::vector<PairCross> pair_cross_;
  int pair_cross_nt_ = 0;  // 0: to make at the next threaded direct pass
  // Scratch of compute_wall_forces, made again after each build: wall contacts by block of
  // bodies and wall axis, and where each block's contacts start in that order.
  std::vector<int> wall_order_, wall_block_off_;
  long wall_order_builds_ = -1;
  std::vector<WallContact> wall_contacts_;
  // Pair contacts of body b: those where b is i are the candidates pair_ioff_[b] ..
  // pair_ioff_[b + 1] (contiguous: sorted by (i, j)); those where b is j have their
  // outputs in pair_out_[pair_jadj_off_[b] .. pair_jadj_off_[b + 1]) (grouped by j, ascending
  // contact index within a group; contact k writes to slot pair_jslot_[k]). The reduction
  // into bodies reads both in a fixed order, contiguously, without a branch per entry.
  // pair_jadj_off_ and pair_jslot_ exist only while the pass keeps its outputs (not after a
  // direct pass, pair_direct_: 16 B a grain less); index_pair_outputs makes them.
  std::vector<int> pair_jadj_off_, pair_jslot_, pair_ioff_, wall_adj_off_, wall_adj_;
  // Cylindrical walls and their contacts (WallContact::wall: the cylinder's index), sorted by
  // (body, cylinder); cyl_adj_off_/cyl_adj_: each body's contacts (CSR, contact order).
  std::vector<CylinderWall> cylinder_walls_;
  std::vector<WallContact> cylinder_contacts_;
  std::vector<int> cyl_adj_off_, cyl_adj_;
  // Triangle-mesh walls: their vertices and triangles (MeshWall's ranges), their contacts
  // (sorted by (body, mesh)), each contact's candidate triangles (CSR: mesh_cand_tri_
  // [mesh_cand_off_[k] ..], indices into mesh_tris_) and each body's contacts (CSR).
  std::vector<MeshWall> mesh_walls_;
  std::vector<Vec3> mesh_vertices_;
  std::vector<std::array<int, 3>> mesh_tris_;
  // Per triangle (as mesh_tris_): its unit normal, (b - a) x (c - a) normalised, and the unit
  // normals of its edges a->b, b->c, c->a in its plane, pointing inwards. A mesh moves by
  // translation only, so they are fixed: computed when the mesh is added (a checkpoint load
  // keeps this scene's where they are the loaded mesh's, else computes them from it).
  std::vector<Vec3> mesh_tri_n_;
  std::vector<std::array<Vec3, 3>> mesh_tri_e_;
  std::vector<MeshContact> mesh_contacts_;
  std::vector<int> mesh_cand_off_, mesh_cand_tri_, mesh_adj_off_, mesh_adj_;
  // Per mesh contact: 1 where its candidate triangles all lie in one plane (a flat patch;
  // index_mesh_contacts, after a build or a checkpoint load; not saved).
  std::vector<std::uint8_t> mesh_flat_;
  // Per mesh contact, written by its pass for the meshes' totals and the reduction into
  // bodies (scratch, not saved): its mesh and count of touching contacts, 4 wall + n (0:
  // none), and each contact's force on the sphere (N), torque on the sphere (N m) and moment
  // term about the mesh's ref (N m), [3 k + j].
  std::vector<int> mesh_sum_code_;
  std::vector<Vec3> mesh_sum_f_, mesh_sum_t_, mesh_sum_m_;
  long mesh_dropped_ = 0;
  // Geogrid.
  int num_nodes_ = 0;
  std::vector<GridLink> links_;
  std::vector<PFacet> facets_;
  std::vector<GridContact> grid_contacts_;
  std::vector<BreakEvent> breaks_;
  Real dropped_plastic_ = 0;   // dissipated by broken or plastic links and broken bonds, J
  std::vector<int> node_link_off_, node_link_;     // node -> incident links (all bodies)
  std::vector<int> link_facet_;                     // 2 per link: incident facets (-1: none)
  std::vector<int> sphere_gc_off_, sphere_gc_;      // sphere -> grid contacts
  std::vector<int> node_gc_off_, node_gc_;          // node -> grid contact * 3 + slot
  // The grid contacts' fields the step reads for every candidate, packed (a GridContact is
  // 472 bytes; most candidates are out of reach), and their status bits: kGridOwner,
  // kGridActive, mirrors of GridContact::owner and ::active, written with them.
  struct GridHot {
    int sphere = 0, prim = 0;
    int node[3] = {0, 0, 0};
    GridPrimitive kind = GridPrimitive::Node;
    std::uint8_t nnodes = 0;
    Real rc = 0;
  };
  static constexpr std::uint8_t kGridOwner = 1, kGridActive = 2;
  std::vector<GridHot> grid_hot_;
  std::vector<std::uint8_t> grid_live_;
  bool grid_topology_dirty_ = true;
  // Bonds.
  std::vector<Bond> bonds_;
  std::vector<BondBreak> bond_breaks_;
  std::vector<int> body_bond_off_, body_bond_;     // body slot -> incident bonds (CSR)
  std::vector<std::pair<int, int>> bond_pairs_;    // (min slot, max slot) of every bond, sorted
  bool bond_topology_dirty_ = true;
  bool grid_wall_contacts_ = false;
  CellGrid grid_;
  // The broad phase's candidate pairs of the last build, rows by i (i < j, sorted by (i, j)):
  // i's partners are entries cand_off_[i] .. cand_off_[i + 1] of cand_j_. During a build (and
  // a checkpoint's load) cand_j_ holds the second bodies; once the records are made, each
  // entry is its record's slot in pairs_ or, without one, ~j (pairs_ above: 4 B a candidate).
  std::vector<int> cand_off_, cand_j_;
  // Dissipation of contacts already dropped from the lists, J.
  Real dropped_friction_ = 0, dropped_viscous_ = 0;
  Real energy_reference_ = 0;  // kinetic + elastic when tracking (re)started, J
  bool energy_reference_set_ = false;

  Real dt_ = 1e-6;
  Vec3 gravity_ = Vec3::Zero();
  Real local_damping_ = 0;
  Real margin_ = 0;  // 0: the default, 0.2 x the mean radius
  Real max_overlap_ratio_ = 0.5;
  Real max_step_ratio_ = 1.0;
  // Smallest radius of a body, m (-1: not known yet; set by rebuild and set_radii, not saved).
  Real min_radius_ = -1;
  Real max_radius_ = 0;  ///< the largest body radius, with min_radius_ (grain_min_radius)
  /// Throws BlowUpError if a body moved more than max_step_ratio of its radius in the step
  /// just integrated (it scans the bodies only when the largest displacement since the last
  /// broad-phase build says one may have).
  void check_tunnelling();
  /// The smallest grain radius (geogrid nodes' where there is no grain), cached until radii
  /// change (min_radius_).
  Real grain_min_radius();
  /// Before a step's passes: no wall, cylinder, mesh or periodic cell moves the bodies' side
  /// of it by more than max_step_ratio x the smallest grain radius in the step (it could pass
  /// a grain without touching it); BlowUpError naming the boundary and its move.
  void check_boundary_steps();
  bool track_energy_ = false;
  ShearKinematics shear_kinematics_ = ShearKinematics::ContactPoint;
  ClumpRotation clump_rotation_ = ClumpRotation::Fincham;
  Real ts_safety_ = 0.8;
  int ts_period_ = 0;
  // Density scaling (set_density_scaling).
  bool ds_on_ = false;
  Real ds_target_dt_ = 0;
  Real ds_safety_ = 0.5;
  int ds_period_ = 1;
  /// Blocked DOFs changed since the last update: the factors are renewed at the next step's
  /// start (before the dt check), whatever the period.
  bool ds_stale_ = false;
  /// Renews the inertia factors (set_density_scaling).
  void update_density_scaling();
  /// Per material, the largest k_n of the linear pair laws it takes part in, N/m (0: none).
  std::vector<Real> stiffest_pair_law() const;
  /// The inertia factor of the body in storage slot b (its clump's for a member), -.
  Real slot_inertia_scale(int b) const;
  /// Sets clump c's factor to s, its angular momentum following its spin.
  void set_clump_scale(int c, Real s);
  /// Per body and axis, the summed translational (kt) and rotational (kr) stiffness of the
  /// active contacts, links and bonds, N/m and N m/rad; false when none is active.
  bool assemble_stiffness(std::vector<Vec3>& kt, std::vector<Vec3>& kr) const;
  /// The critical step of clump c and of free body b from the stiffnesses (inertia times
  /// its factor when `scaled`), s; infinite when unconstrained or fully blocked.
  Real clump_critical_dt(int c, const std::vector<Vec3>& kt, const std::vector<Vec3>& kr,
                         bool scaled) const;
  Real body_critical_dt(int b, const std::vector<Vec3>& kt, const std::vector<Vec3>& kr,
                        bool scaled) const;
  mutable std::vector<Vec3> ds_kt_, ds_kr_;  // scratch of update_density_scaling
  int dt_check_period_ = 100;
  /// The stiffest contact that formed since the last dt check: the passes note every contact
  /// that takes its parameters (update_phys: a contact forms, or its materials changed) with
  /// its k_n over the mass of its lighter free body (1/s^2; -1: none formed) and that body.
  /// Written by the passes' threads only when a contact forms; read and cleared by check_dt.
  /// Not saved, and not copied with the scene.
  struct FormedContacts {
    std::atomic<Real> stiffness_per_mass{-1};
    int body = -1;
    long since = 0;  // the step of the last check
    std::mutex lock;
    FormedContacts() = default;
    FormedContacts(const FormedContacts&) {}
    FormedContacts& operator=(const FormedContacts&) { return *this; }
  };
  mutable FormedContacts formed_;
  /// Notes a contact between bodies b1 and b2 (-1: a wall, or a grid node whose links bound
  /// its step) that took the parameters p (see formed_).
  void note_formed_contact(const ContactPhys& p, int b1, int b2) const;
  /// The dt check (set_dt_check_period).
  void check_dt();
  /// The end of a blow-up's message (overlap, tunnelling) of body b: dt against the critical
  /// estimate and, when b's material is soft against its weight, that material's modulus.
  std::string blow_up_hint(int b) const;
  long step_ = 0;
  Real time_ = 0;
  int phys_version_ = 0;
  bool dirty_ = true;
  long builds_ = 0;
  // Largest broad-phase displacement measured by the last integration pass (valid while
  // nothing else moved bodies or changed radii since); not saved in checkpoints.
  Real max_disp_ = 0;
  bool disp_valid_ = false;
};

template <class F>
void Scene::for_each_contact(F&& f) const {
  for_each_contact_of(ContactKind::Pair, f);
  for_each_contact_of(ContactKind::Wall, f);
  for_each_contact_of(ContactKind::Grid, f);
  if (!cylinder_contacts_.empty()) for_each_contact_of(ContactKind::Cylinder, f);
  if (!mesh_contacts_.empty()) for_each_contact_of(ContactKind::Mesh, f);
}

template <class F>
void Scene::for_each_contact_of(ContactKind kind, F&& f) const {
  ContactRecord r;
  r.kind = kind;
  if (kind == ContactKind::Pair) {
    ContactState scratch;
    ContactPhys phys;
    r.state = &scratch;
    r.phys = &phys;
    // (every candidate pair, in (i, j) order; one without a record as a fresh one)
    const int nrows = static_cast<int>(pair_ioff_.size()) - 1;
    for (int i = 0; i < nrows; ++i) {
      for (int k = pair_ioff_[i]; k < pair_ioff_[i + 1]; ++k) {
        const int s = cand_slot(k);
        r.index = static_cast<long>(k);
        r.active = s >= 0 && pairs_[s].active;
        r.body1 = i;
        r.body2 = cand_second(k);
        phys = pair_phys(k);
        scratch = pair_state(k);
        r.force2 = pair_force(k);
        r.shift2 = pair_shift(k);
        r.arm1 = bodies_.radius[i] - 0.5 * scratch.overlap;
        r.arm2 = bodies_.radius[r.body2] - 0.5 * scratch.overlap;
        f(static_cast<const ContactRecord&>(r));
      }
    }
  } else if (kind == ContactKind::Wall || kind == ContactKind::Cylinder) {
    const auto& contacts = kind == ContactKind::Wall ? wall_contacts_ : cylinder_contacts_;
    for (size_t k = 0; k < contacts.size(); ++k) {
      const WallContact& c = contacts[k];
      r.index = static_cast<long>(k);
      r.active = c.active;
      r.body2 = c.body;
      r.other = c.wall;
      r.phys = &c.phys;
      r.state = &c.state;
      r.force2 = c.force;
      r.arm2 = bodies_.radius[c.body] - 0.5 * c.state.overlap;
      f(static_cast<const ContactRecord&>(r));
    }
  } else if (kind == ContactKind::Mesh) {
    // Each of a sphere–mesh pair's contacts (faces, edges, vertices) is one record.
    for (size_t k = 0; k < mesh_contacts_.size(); ++k) {
      const MeshContact& c = mesh_contacts_[k];
      for (int s = 0; s < MeshContact::kMaxSubs; ++s) {
        const MeshSub& sub = c.subs[s];
        r.index = static_cast<long>(k) * MeshContact::kMaxSubs + s;
        r.active = c.active && sub.kind >= 0;
        r.body2 = c.body;
        r.other = c.wall;
        r.phys = &c.phys;
        r.state = &sub.state;
        r.force2 = sub.force;
        r.arm2 = bodies_.radius[c.body] - 0.5 * sub.state.overlap;
        f(static_cast<const ContactRecord&>(r));
      }
    }
  } else {
    for (size_t k = 0; k < grid_contacts_.size(); ++k) {
      const GridContact& c = grid_contacts_[k];
      r.index = static_cast<long>(k);
      r.active = c.active;
      r.body2 = c.sphere;
      r.other = c.prim;
      r.phys = &c.phys;
      r.state = &c.state;
      r.force2 = c.force;
      r.arm1 = c.rc - 0.5 * c.state.overlap;
      r.arm2 = bodies_.radius[c.sphere] - 0.5 * c.state.overlap;
      f(static_cast<const ContactRecord&>(r));
    }
  }
}

}  // namespace cpp_dem
