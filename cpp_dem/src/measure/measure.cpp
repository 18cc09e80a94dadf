// Measurements: time-step estimates, energies, unbalanced force.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

Real Scene::pwave_dt() const {
  Real dt = std::numeric_limits<Real>::infinity();
  for (int b = 0; b < num_bodies(); ++b) {
    // A fully blocked body sets no limit (a clump member: when its clump is fully blocked).
    const int c = bodies_.clump[b];
    if (((c >= 0 ? clumps_.blocked[c] : bodies_.blocked[b]) & DOF_ALL) == DOF_ALL) continue;
    const Material& m = materials_[bodies_.material[b]];
    dt = std::min(dt, bodies_.radius[b] * std::sqrt(m.density / m.young));
  }
  return dt;  // infinite when every body is fully blocked
}

Real Scene::critical_dt() const { return critical_dt_body(nullptr); }

bool Scene::assemble_stiffness(std::vector<Vec3>& kt, std::vector<Vec3>& kr) const {
  // Per body and axis, the summed contact stiffness K_a (translation) and K_a^rot.
  const int n = num_bodies();
  kt.assign(n, Vec3::Zero());
  kr.assign(n, Vec3::Zero());
  bool any = false;
  auto add = [&](int b, const Vec3& nrm, Real kn, Real ks, Real arm, Real krol) {
    for (int a = 0; a < 3; ++a) {
      const Real n2 = nrm[a] * nrm[a];
      kt[b][a] += kn * n2 + ks * (1 - n2);
      kr[b][a] += ks * arm * arm * (1 - n2) + krol;
    }
  };
  for_each_contact([&](const ContactRecord& c) {
    if (!c.active) return;
    any = true;
    Real kn, ks;
    c.stiffness(kn, ks);
    const Real krol = c.phys->kr;
    if (c.body1 >= 0) add(c.body1, c.state->normal, kn, ks, c.arm1, krol);
    add(c.body2, c.state->normal, kn, ks, c.arm2, krol);
    if (c.kind == ContactKind::Grid) {
      // The virtual sphere's share goes to the primitive's nodes by their weights.
      const GridContact& g = grid_contacts_[c.index];
      for (int i = 0; i < g.nnodes; ++i)
        if (g.w[i] > 0)
          add(g.node[i], c.state->normal, g.w[i] * kn, g.w[i] * ks, g.rc, g.w[i] * krol);
    }
  });
  for (const GridLink& l : links_) {
    if (l.broken) continue;
    any = true;
    const Real half = 0.5 * (bodies_.pos[l.b] - bodies_.pos[l.a]).norm();
    for (int side = 0; side < 2; ++side) {
      const int b = side ? l.b : l.a;
      for (int a = 0; a < 3; ++a) {
        const Real n2 = l.normal[a] * l.normal[a];
        kt[b][a] += l.kn * n2 + l.ks * (1 - n2);
        kr[b][a] += l.kr * (1 - n2) + l.ktw * n2 + l.ks * half * half * (1 - n2);
      }
    }
  }
  for (const Bond& l : bonds_) {
    // The linear contact (when it acts) and the parallel bond, as springs at the contact
    // point; the parallel bond's twisting and bending springs.
    Real kn, ks;
    l.stiffness(kn, ks);
    if (!(kn > 0 || ks > 0)) continue;
    any = true;
    const Real ktw = l.pb_intact ? l.pb_ks * l.pb_j : 0, kbend = l.pb_intact ? l.pb_kn * l.pb_i : 0;
    for (int side = 0; side < 2; ++side) {
      const int b = side ? l.b : l.a;
      const Real arm = bodies_.radius[b];
      for (int a = 0; a < 3; ++a) {
        const Real n2 = l.normal[a] * l.normal[a];
        kt[b][a] += kn * n2 + ks * (1 - n2);
        kr[b][a] += kbend * (1 - n2) + ktw * n2 + ks * arm * arm * (1 - n2);
      }
    }
  }
  return any;
}

Real Scene::clump_critical_dt(int c, const std::vector<Vec3>& kt, const std::vector<Vec3>& kr,
                              bool scaled) const {
  // The members' stiffnesses summed (translation), and for rotation each member's largest
  // translational stiffness at its lever arm plus its rotational one, against the smallest
  // principal moment.
  Vec3 ktc = Vec3::Zero(), krc = Vec3::Zero();
  const Mat3& rot = clumps_.rot[c];
  for (int e = clumps_.member_off[c]; e < clumps_.member_off[c + 1]; ++e) {
    const int s = clumps_.member[e];
    ktc += kt[s];
    const Real arm2 = (rot * clumps_.member_local[e]).squaredNorm();
    krc += kr[s] + Vec3::Constant(kt[s].maxCoeff() * arm2);
  }
  const Real f = scaled ? clumps_.inertia_scale[c] : 1.0;
  const Real m = clumps_.mass[c] * f, imin = clumps_.inertia[c].minCoeff() * f;
  Real d = std::numeric_limits<Real>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (ktc[a] > 0 && !(clumps_.blocked[c] & (DOF_X << a))) d = std::min(d, std::sqrt(2 * m / ktc[a]));
    if (krc[a] > 0 && !(clumps_.blocked[c] & (DOF_RX << a))) d = std::min(d, std::sqrt(2 * imin / krc[a]));
  }
  return d;
}

Real Scene::body_critical_dt(int b, const std::vector<Vec3>& kt, const std::vector<Vec3>& kr,
                             bool scaled) const {
  const Real f = scaled ? bodies_.inertia_scale_of(b) : 1.0;
  const Real m = bodies_.mass[b] * f, inertia = bodies_.inertia[b] * f;
  Real d = std::numeric_limits<Real>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (kt[b][a] > 0 && !(bodies_.blocked[b] & (DOF_X << a))) d = std::min(d, std::sqrt(2 * m / kt[b][a]));
    if (kr[b][a] > 0 && !(bodies_.blocked[b] & (DOF_RX << a))) d = std::min(d, std::sqrt(2 * inertia / kr[b][a]));
  }
  return d;
}

Real Scene::critical_dt_body(int* arg_body, bool contact_seen) const {
  // Per body and axis the estimate sqrt(2 m / K_a) is a Gershgorin bound on 2 / omega_max
  // for the assembled system: exact for two equal spheres in contact, sqrt(2) below the
  // exact value for a sphere against a rigid wall.
  const int n = num_bodies();
  std::vector<Vec3> kt, kr;
  const bool any = assemble_stiffness(kt, kr) || contact_seen;
  if (arg_body) *arg_body = -1;
  if (!any) return pwave_dt();
  // A sphere with no (or only soft) contacts may hit something before the next update: its
  // stiffness per axis is at least that of one contact with an equal sphere, E R (the linear
  // law's k_n). Without this floor the estimate followed only the bodies in contact, and in
  // a 1:20 PSD the first big-big contact lifted dt 36-fold above what a small grain needs.
  // A pair law's own k_n (Scene::set_pair_law) may be stiffer than E R: the floor of a
  // body takes the stiffest pair law of its material too (else a grain with no contact yet
  // took a step that is unstable once it touches, e.g. a soft grain on 002's stiff grid).
  // With density scaling the floor is left out: the scaling follows each body's own
  // contacts (set_density_scaling), and the estimate is that of the scaled inertia.
  if (!ds_on_) {
    const std::vector<Real> law_kn = stiffest_pair_law();
    for (int b = 0; b < n; ++b) {
      if (bodies_.kind[b] != BODY_SPHERE) continue;
      const int m = bodies_.material[b];
      const Real floor_k = std::max(materials_[m].young * bodies_.radius[b], law_kn[m]);
      for (int a = 0; a < 3; ++a) kt[b][a] = std::max(kt[b][a], floor_k);
    }
  }
  Real dt = std::numeric_limits<Real>::infinity();
  // Clump members are fully blocked bodies and set no limit below.
  for (int c = 0; c < clumps_.size(); ++c) {
    const Real d = clump_critical_dt(c, kt, kr, ds_on_);
    if (d < dt) {
      dt = d;
      if (arg_body) *arg_body = id_of(clumps_.member[clumps_.member_off[c]]);
    }
  }
  for (int b = 0; b < n; ++b) {
    const Real d = body_critical_dt(b, kt, kr, ds_on_);
    if (d < dt) {
      dt = d;
      if (arg_body) *arg_body = id_of(b);
    }
  }
  return std::isfinite(dt) ? dt : pwave_dt();
}

std::vector<Real> Scene::stiffest_pair_law() const {
  std::vector<Real> law_kn(materials_.size(), 0.0);
  for (const PairLaw& l : pair_laws_) {
    if (!(l.kn > 0)) continue;
    law_kn[l.a] = std::max(law_kn[l.a], l.kn);
    law_kn[l.b] = std::max(law_kn[l.b], l.kn);
  }
  return law_kn;
}

void Scene::update_density_scaling() {
  ds_stale_ = false;
  assemble_stiffness(ds_kt_, ds_kr_);  // (zero for a body with nothing active: factor 1)
  // A single body already in contact (not a clump member) is scaled for one more contact of
  // the stiffest linear pair law of its material as well: such a contact acts at full
  // stiffness the step it forms, which may come between two updates (a light bonded grid
  // sphere touched by a grain). A body with nothing active keeps 1 (it falls at g).
  const std::vector<Real> law_kn = stiffest_pair_law();
  for (int b = 0; b < num_bodies(); ++b) {
    const Real k = law_kn[bodies_.material[b]];
    if (k > 0 && bodies_.clump[b] < 0 && ds_kt_[b].maxCoeff() > 0) ds_kt_[b].array() += k;
  }
  const Real h = ds_target_dt_ / ds_safety_;  // the critical step every body must reach, s
  // A factor rises at once to what the contacts need, and falls at most by half per
  // update: a body that bounces off a contact keeps its inertia for the next touch (which
  // may come before the next update), and a body that has left its contacts for good is back
  // at 1 within a few updates.
  const auto factor = [h](Real d, Real old) {
    const Real need = std::isfinite(d) && d < h ? (h / d) * (h / d) : 1.0;
    return std::max(need, std::max(1.0, 0.5 * old));
  };
  for (int c = 0; c < clumps_.size(); ++c)
    set_clump_scale(c, factor(clump_critical_dt(c, ds_kt_, ds_kr_, false), clumps_.inertia_scale[c]));
  const int n = num_bodies();
  if (bodies_.inertia_scale.empty()) bodies_.inertia_scale.assign(n, 1.0);  // (the first factors)
  for (int b = 0; b < n; ++b) {
    const Real s = bodies_.clump[b] >= 0
                       ? 1.0
                       : factor(body_critical_dt(b, ds_kt_, ds_kr_, false), bodies_.inertia_scale[b]);
    Real& old = bodies_.inertia_scale[b];
    // (The kinetic energy changes with the factor; the balance books it as external work.)
    if (track_energy_ && s != old) bodies_.ext_work[b] += bodies_.ke[b] * (s / old - 1);
    old = s;
  }
}

Scene::DensityScalingStats Scene::density_scaling_stats() const {
  DensityScalingStats st;
  Real mass = 0, scaled_mass = 0;
  const auto count = [&](Real m, Real f, std::uint8_t blocked) {
    if ((blocked & DOF_ALL) == DOF_ALL) return;
    ++st.movable;
    mass += m;
    scaled_mass += f * m;
    st.max_factor = std::max(st.max_factor, f);
    if (f > 1) ++st.scaled;
  };
  for (int c = 0; c < clumps_.size(); ++c)
    count(clumps_.mass[c], clumps_.inertia_scale[c], clumps_.blocked[c]);
  for (int b = 0; b < num_bodies(); ++b)
    if (bodies_.clump[b] < 0) count(bodies_.mass[b], bodies_.inertia_scale_of(b), bodies_.blocked[b]);
  st.mean_factor = mass > 0 ? scaled_mass / mass : 1.0;
  st.scaled_share = st.movable > 0 ? static_cast<Real>(st.scaled) / st.movable : 0.0;
  // The inertial number over the active pair contacts, in contact order.
  Real num = 0, den = 0;
  const bool cell = cell_.on;
  for_each_contact_of(ContactKind::Pair, [&](const ContactRecord& c) {
    if (!c.active) return;
    const Real f = c.force2.norm();
    if (!(f > 0)) return;
    const int i = c.body1, j = c.body2;
    Vec3 dv = bodies_.vel[j] - bodies_.vel[i];
    if (cell) dv += cell_.vel_grad * c.shift2;
    const Real d = bodies_.radius[i] + bodies_.radius[j];
    const Real rho = 0.5 * (materials_[bodies_.material[i]].density * slot_inertia_scale(i) +
                            materials_[bodies_.material[j]].density * slot_inertia_scale(j));
    num += rho * dv.squaredNorm();
    den += f / (d * d);
  });
  st.inertial_number = den > 0 ? std::sqrt(num / den) : 0.0;
  return st;
}

Real Scene::slot_inertia_scale(int b) const {
  const int c = bodies_.clump[b];
  return c >= 0 ? clumps_.inertia_scale[c] : bodies_.inertia_scale_of(b);
}

Real Scene::inertia_scale(int id) const {
  check_body(id);
  return slot_inertia_scale(slot_of(id));
}

Energies Scene::energies() const {
  Energies e;
  // (the accumulators exist once the scene has tracked energy: BodyStore::size_energy)
  const int n = static_cast<int>(bodies_.ke.size());
  const int nc = static_cast<int>(clumps_.ke.size());
  for (int c = 0; c < nc; ++c) {
    e.kinetic += clumps_.ke[c];
    e.gravity_potential += -clumps_.mass[c] * gravity_.dot(clumps_.pos[c] - clumps_.pos_at_energy_reset[c]);
    e.local_damping += clumps_.damp_dissip[c];
    e.external_work += clumps_.ext_work[c];
  }
  for (int b = 0; b < n; ++b) {
    if (bodies_.clump[b] >= 0) continue;  // counted with its clump
    e.kinetic += bodies_.ke[b];
    e.gravity_potential += -bodies_.mass[b] * gravity_.dot(bodies_.pos[b] - bodies_.pos_at_energy_reset[b]);
    e.local_damping += bodies_.damp_dissip[b];
    e.external_work += bodies_.ext_work[b];
  }
  e.friction = dropped_friction_;
  e.viscous = dropped_viscous_;
  for_each_contact([&e](const ContactRecord& c) {
    e.friction += c.state->dissip_friction;
    e.viscous += c.state->dissip_viscous;
  });
  e.plastic = dropped_plastic_;
  for (const GridLink& l : links_) e.plastic += l.dissip_plastic;
  for (const Bond& l : bonds_) e.friction += l.dissip_friction;
  e.elastic = stored_elastic_energy();
  for (const Wall& w : walls_) e.wall_work += w.work;
  for (const CylinderWall& w : cylinder_walls_) e.wall_work += w.work;
  for (const MeshWall& w : mesh_walls_) e.wall_work += w.work;
  e.cell_work = cell_.work;
  if (!track_energy_ || !energy_reference_set_) return e;
  // The potential of gravity is taken at the positions where the kinetic energy was sampled
  // (the start of the last step): move back by v dt.
  for (int b = 0; b < n; ++b)
    if (bodies_.clump[b] < 0) e.gravity_potential += bodies_.mass[b] * gravity_.dot(bodies_.vel[b]) * dt_;
  for (int c = 0; c < clumps_.size(); ++c)
    e.gravity_potential += clumps_.mass[c] * gravity_.dot(clumps_.vel[c]) * dt_;
  const Real now = e.kinetic + e.elastic + e.gravity_potential + e.friction + e.viscous +
                   e.local_damping + e.plastic - e.wall_work - e.external_work - e.cell_work;
  e.balance_error = now - energy_reference_;
  const Real scale = std::abs(e.kinetic) + std::abs(e.elastic) + std::abs(e.gravity_potential) +
                     e.friction + e.viscous + e.local_damping + e.plastic + std::abs(e.wall_work) +
                     std::abs(e.external_work) + std::abs(e.cell_work) + std::abs(energy_reference_);
  e.balance_error_relative = scale > 0 ? std::abs(e.balance_error) / scale : 0.0;
  return e;
}

void Scene::reset_energy() {
  // (the accumulators exist once the scene has tracked energy: BodyStore::size_energy)
  const int n = static_cast<int>(bodies_.ke.size());
  for (int b = 0; b < n; ++b) {
    bodies_.damp_dissip[b] = 0;
    bodies_.ext_work[b] = 0;
    bodies_.ke[b] = 0;
    bodies_.pos_at_energy_reset[b] = bodies_.pos[b];
  }
  for (int c = 0; c < static_cast<int>(clumps_.ke.size()); ++c) {
    clumps_.damp_dissip[c] = clumps_.ext_work[c] = clumps_.ke[c] = 0;
    clumps_.pos_at_energy_reset[c] = clumps_.pos[c];
  }
  dropped_friction_ = dropped_viscous_ = 0;
  std::fill(pair_dissip_.begin(), pair_dissip_.end(), 0.0);
  for (PairContactCold& c : pair_cold_) c.dissip_viscous = 0;
  for (WallContact& c : wall_contacts_) c.state.dissip_friction = c.state.dissip_viscous = 0;
  for (WallContact& c : cylinder_contacts_) c.state.dissip_friction = c.state.dissip_viscous = 0;
  for (MeshContact& c : mesh_contacts_)
    for (MeshSub& s : c.subs) s.state.dissip_friction = s.state.dissip_viscous = 0;
  for (GridContact& c : grid_contacts_) c.state.dissip_friction = c.state.dissip_viscous = 0;
  for (GridLink& l : links_) l.dissip_plastic = 0;
  for (Bond& l : bonds_) l.dissip_friction = 0;
  dropped_plastic_ = 0;
  for (Wall& w : walls_) w.work = 0;
  for (CylinderWall& w : cylinder_walls_) w.work = 0;
  for (MeshWall& w : mesh_walls_) w.work = 0;
  cell_.work = 0;
  // The reference (kinetic + elastic) is taken in the next step, once the contacts of the
  // current positions have been evaluated, so energy stored in initial overlaps counts.
  energy_reference_set_ = false;
  energy_reference_ = 0;
}

Real Scene::stored_elastic_energy() const {
  Real e = 0;
  for_each_contact([&e](const ContactRecord& c) {
    if (c.active) e += c.elastic_energy();
  });
  for (const GridLink& l : links_)
    if (!l.broken) e += l.elastic_energy();
  for (const Bond& l : bonds_) e += l.elastic_energy();
  return e;
}

void Scene::set_energy_reference() {
  Real e = stored_elastic_energy();
  for (int b = 0; b < num_bodies(); ++b)
    if (bodies_.clump[b] < 0)
      e += 0.5 * bodies_.mass[b] * bodies_.vel[b].squaredNorm() + 0.5 * bodies_.inertia[b] * bodies_.angvel[b].squaredNorm();
  for (int c = 0; c < clumps_.size(); ++c)
    e += 0.5 * clumps_.mass[c] * clumps_.vel[c].squaredNorm() + 0.5 * clumps_.angvel[c].dot(clumps_.angmom[c]);
  energy_reference_ = e;
  energy_reference_set_ = true;
}

Real Scene::unbalanced_force() const {
  // Yade's definition: mean resultant force on free bodies over mean contact force.
  Real sum_f = 0;
  int nfree = 0;
  for (int b = 0; b < num_bodies(); ++b) {
    if (bodies_.blocked[b] & DOF_XYZ) continue;
    sum_f += bodies_.force[b].norm();
    ++nfree;
  }
  Real sum_c = 0;
  int nc = 0;
  for_each_contact([&](const ContactRecord& c) {
    if (!c.active) return;
    sum_c += c.force2.norm();
    ++nc;
  });
  for (int c = 0; c < clumps_.size(); ++c) {
    if (clumps_.blocked[c] & DOF_XYZ) continue;
    sum_f += clumps_.force[c].norm();
    ++nfree;
  }
  if (nfree == 0 || nc == 0 || sum_c == 0) return std::numeric_limits<Real>::quiet_NaN();
  return (sum_f / nfree) / (sum_c / nc);
}

std::vector<std::pair<std::string, std::size_t>> Scene::memory_by_field() const {
  std::vector<std::pair<std::string, std::size_t>> out;
  const auto add = [&](const char* name, const auto& v) {
    out.emplace_back(name, v.capacity() * sizeof(v[0]));
  };
#define CPP_DEM_MEM(prefix, store, field) add(prefix #field, store.field)
#define CPP_DEM_BODY(field) CPP_DEM_MEM("bodies.", bodies_, field)
  CPP_DEM_BODY(pos); CPP_DEM_BODY(vel); CPP_DEM_BODY(angvel); CPP_DEM_BODY(force);
  CPP_DEM_BODY(torque); CPP_DEM_BODY(ext_force); CPP_DEM_BODY(ext_torque); CPP_DEM_BODY(ori);
  CPP_DEM_BODY(radius); CPP_DEM_BODY(mass); CPP_DEM_BODY(inertia); CPP_DEM_BODY(material);
  CPP_DEM_BODY(blocked); CPP_DEM_BODY(kind); CPP_DEM_BODY(clump); CPP_DEM_BODY(image);
  CPP_DEM_BODY(ke); CPP_DEM_BODY(damp_dissip); CPP_DEM_BODY(ext_work);
  CPP_DEM_BODY(pos_at_energy_reset); CPP_DEM_BODY(inertia_scale);
#undef CPP_DEM_BODY
#define CPP_DEM_CLUMP(field) CPP_DEM_MEM("clumps.", clumps_, field)
  CPP_DEM_CLUMP(pos); CPP_DEM_CLUMP(vel); CPP_DEM_CLUMP(angvel); CPP_DEM_CLUMP(angmom);
  CPP_DEM_CLUMP(ori); CPP_DEM_CLUMP(rot); CPP_DEM_CLUMP(force); CPP_DEM_CLUMP(torque);
  CPP_DEM_CLUMP(ext_force); CPP_DEM_CLUMP(ext_torque); CPP_DEM_CLUMP(mass);
  CPP_DEM_CLUMP(inertia); CPP_DEM_CLUMP(stiffness_radius); CPP_DEM_CLUMP(blocked);
  CPP_DEM_CLUMP(member_off); CPP_DEM_CLUMP(ke); CPP_DEM_CLUMP(damp_dissip);
  CPP_DEM_CLUMP(ext_work); CPP_DEM_CLUMP(pos_at_energy_reset); CPP_DEM_CLUMP(inertia_scale);
  CPP_DEM_CLUMP(member); CPP_DEM_CLUMP(member_local);
#undef CPP_DEM_CLUMP
#undef CPP_DEM_MEM
  add("order.id_of_slot", id_of_slot_);
  add("order.slot_of_id", slot_of_id_);
  add("broadphase.pos_at_build", pos_at_build_);
  add("broadphase.radius_at_build", radius_at_build_);
  add("broadphase.candidates", cand_j_);
  add("broadphase.candidate_off", cand_off_);
  add("broadphase.candidate_images", candidate_images_);
  grid_.add_memory(out);
  add("contacts.pairs", pairs_);
  add("contacts.pair_cold", pair_cold_);
  add("contacts.pair_dissip", pair_dissip_);
  add("contacts.pair_out", pair_out_);
  add("contacts.pair_jadj_off", pair_jadj_off_);
  add("contacts.pair_jslot", pair_jslot_);
  add("contacts.pair_ioff", pair_ioff_);
  add("contacts.walls", wall_contacts_);
  add("contacts.wall_adj_off", wall_adj_off_);
  add("contacts.wall_adj", wall_adj_);
  add("scratch.pair_fi", pair_fi_);
  add("scratch.pair_ti", pair_ti_);
  add("scratch.pair_cross", pair_cross_);
  add("scratch.pair_cross_k", pair_cross_k_);
  add("scratch.pair_cross_t", pair_cross_t_);
  add("scratch.pair_cross_j", pair_cross_j_);
  add("scratch.pair_cross_jt", pair_cross_jt_);
  add("scratch.pair_cross_b", pair_cross_b_);
  {
    // (each thread's new records of the last pass, and the list of them)
    std::size_t bytes = pair_new_.capacity() * sizeof(pair_new_[0]);
    for (const auto& v : pair_new_) bytes += v.capacity() * sizeof(NewPair);
    out.emplace_back("scratch.pair_new", bytes);
  }
  add("scratch.wall_order", wall_order_);
  add("scratch.wall_block_off", wall_block_off_);
  add("scratch.density_scaling_kt", ds_kt_);
  add("scratch.density_scaling_kr", ds_kr_);
  add("walls.walls", walls_);
  add("walls.openings", wall_openings_);
  add("walls.cylinders", cylinder_walls_);
  add("contacts.cylinders", cylinder_contacts_);
  add("contacts.cyl_adj_off", cyl_adj_off_);
  add("contacts.cyl_adj", cyl_adj_);
  add("walls.meshes", mesh_walls_);
  add("walls.mesh_vertices", mesh_vertices_);
  add("walls.mesh_triangles", mesh_tris_);
  add("walls.mesh_triangle_normals", mesh_tri_n_);
  add("walls.mesh_edge_normals", mesh_tri_e_);
  add("contacts.meshes", mesh_contacts_);
  add("contacts.mesh_cand_off", mesh_cand_off_);
  add("contacts.mesh_cand_tri", mesh_cand_tri_);
  add("contacts.mesh_flat", mesh_flat_);
  add("contacts.mesh_sum_code", mesh_sum_code_);
  add("contacts.mesh_sum_f", mesh_sum_f_);
  add("contacts.mesh_sum_t", mesh_sum_t_);
  add("contacts.mesh_sum_m", mesh_sum_m_);
  add("contacts.mesh_adj_off", mesh_adj_off_);
  add("contacts.mesh_adj", mesh_adj_);
  add("geogrid.links", links_);
  add("geogrid.pfacets", facets_);
  add("geogrid.contacts", grid_contacts_);
  add("geogrid.breaks", breaks_);
  add("geogrid.node_link_off", node_link_off_);
  add("geogrid.node_link", node_link_);
  add("geogrid.link_facet", link_facet_);
  add("geogrid.sphere_gc_off", sphere_gc_off_);
  add("geogrid.sphere_gc", sphere_gc_);
  add("geogrid.node_gc_off", node_gc_off_);
  add("geogrid.node_gc", node_gc_);
  add("bonds.bonds", bonds_);
  add("bonds.breaks", bond_breaks_);
  add("bonds.body_bond_off", body_bond_off_);
  add("bonds.body_bond", body_bond_);
  add("bonds.pairs", bond_pairs_);
  add("materials.materials", materials_);
  add("materials.pair_laws", pair_laws_);
  return out;
}

}  // namespace cpp_dem
