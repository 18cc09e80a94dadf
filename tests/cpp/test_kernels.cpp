// Kernel tests of the contact-law parts and shape-pair units, on plain values (no scene).
// Built and run by tests/test_cpp_kernels.py; prints one line per check and "N passed, M
// failed" at the end, exits 1 on a failure.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

#include "cpp_dem/geometry/sphere_grid.hpp"
#include "cpp_dem/geometry/sphere_sphere.hpp"
#include "cpp_dem/geometry/sphere_wall.hpp"
#include "cpp_dem/laws/beam.hpp"
#include "cpp_dem/laws/contact_law.hpp"
#include "cpp_dem/laws/registry.hpp"

using namespace cpp_dem;

namespace {
int passed = 0, failed = 0;
void check(bool ok, const std::string& what, double got = NAN, double want = NAN) {
  std::printf("%s %s", ok ? "ok  " : "FAIL", what.c_str());
  if (!std::isnan(got) || !std::isnan(want)) std::printf(" (got %.17g, want %.17g)", got, want);
  std::printf("\n");
  (ok ? passed : failed)++;
}
bool close(double a, double b, double rel) { return std::abs(a - b) <= rel * std::abs(b); }
}  // namespace

int main() {
  // ---- Coulomb cap (000 eq 3) -----------------------------------------------------------
  {
    Vec3 fs(3.0, 4.0, 0.0);  // |fs| = 5 N
    Real dissip = 0;
    const bool slip = cap_magnitude<NarrowOps>(fs, 2.5, 100.0, dissip);
    check(slip, "cap: |fs| = 5 N above a 2.5 N cap slips");
    check(close(fs.norm(), 2.5, 1e-15), "cap: capped magnitude is the cap", fs.norm(), 2.5);
    check(close(fs[0] / fs[1], 0.75, 1e-15), "cap: direction kept", fs[0] / fs[1], 0.75);
    // (fs_trial - fs) . fs / k = (5 - 2.5) * 2.5 / 100.
    check(close(dissip, 2.5 * 2.5 / 100.0, 1e-14), "cap: slip energy (f_trial - f).f / k",
          dissip, 0.0625);
    Vec3 small(0.1, 0.0, 0.0);
    Real d2 = 0;
    check(!cap_magnitude<NarrowOps>(small, 2.5, 100.0, d2) && small[0] == 0.1 && d2 == 0,
          "cap: a force below the cap is untouched");
    // The wall's 2-vector form gives the same numbers.
    Tan2 t{3.0, 4.0};
    Real d3 = 0;
    cap_magnitude<PlaneOps>(t, 2.5, 100.0, d3);
    check(t.a == fs[0] && t.b == fs[1] && d3 == dissip, "cap: plane form equals 3-vector form");
    // A spring with a dashpot: the cap acts on the total, the spring takes the capped total.
    Vec3 spring(1.0, 0.0, 0.0), visc(2.0, 0.0, 0.0);
    Real d4 = 0;
    cap_spring<NarrowOps>(spring, Vec3(spring + visc), 1.5, 10.0, d4);
    check(spring[0] == 1.5 && close(d4, (1.0 - 1.5) * 1.5 / 10.0, 1e-15),
          "cap: spring + dashpot total capped into the spring", spring[0], 1.5);
  }
  // ---- frame turn ---------------------------------------------------------------------
  {
    // A normal turning by a small angle about z carries the shear force with it (to first
    // order), and leaves it in the new tangent plane.
    const Real a = 1e-4;
    const Vec3 n_old(1, 0, 0), n(std::cos(a), std::sin(a), 0);
    Vec3 fs(0, 2.0, 0), axis, twist;
    frame_turn<NarrowOps>(n_old, n, Vec3::Zero().eval(), 1e-5, axis, twist);
    turn_into_frame<NarrowOps>(fs, axis, twist, n);
    check(std::abs(fs.dot(n)) < 1e-15, "frame: shear force in the new tangent plane", fs.dot(n), 0);
    check(close(fs.norm(), 2.0, 1e-7), "frame: magnitude kept to second order", fs.norm(), 2.0);
    // A spin about the normal turns fs by dt/2 (w1 + w2) . n to first order.
    Vec3 f2(0, 1.0, 0), ax2, tw2;
    const Vec3 nn(1, 0, 0);
    frame_turn<NarrowOps>(nn, nn, Vec3(20.0, 0, 0), 1e-5, ax2, tw2);
    turn_into_frame<NarrowOps>(f2, ax2, tw2, nn);
    check(close(f2[2], 0.5 * 1e-5 * 20.0, 1e-12), "frame: twist about the normal", f2[2], 1e-4);
  }
  // ---- the short kernel equals the composed law with its parts off ----------------------
  {
    ContactPhys p;
    p.model = ContactModel::Linear;
    p.kn = 1e5;
    p.ks = 3e4;
    p.tan_phi = 0.5;
    ContactState s;
    s.fs = Vec3(0.0, 0.3, 0.1);
    s.normal = Vec3(0.999, 0.0447, 0).normalized();
    ContactGeometry g;
    g.normal = Vec3(1, 0, 0);
    g.overlap = 2e-5;
    g.rel_vel = Vec3(-0.01, 0.2, -0.05);
    g.angvel_sum = Vec3(3.0, -1.0, 2.0);
    g.rel_angvel = Vec3::Zero();
    ContactState s_law = s;
    const LawOutput out = apply_law(p, g, 1e-5, s_law);
    Vec3 fs = s.fs;
    Real dissip = 0;
    const Real fn = linear_frictional<NarrowOps>(fs, s.normal, g.normal, g.overlap, g.rel_vel,
                                                 g.angvel_sum, p.kn, p.ks, p.tan_phi, 1e-5, dissip);
    check(fn == s_law.fn && fs == s_law.fs && dissip == s_law.dissip_friction,
          "short kernel == composed law (linear, no dashpot, no rolling), bitwise");
    check((out.force2 - (fn * g.normal + fs)).norm() == 0, "short kernel force == law force");
    check(short_kernel_applies(p), "registry: a plain linear contact takes the short kernel");
    p.kr = 1.0;
    check(!short_kernel_applies(p), "registry: rolling resistance takes the composed law");
  }
  // ---- the Hertz–Mindlin short kernel equals the composed law, in both vector forms -------
  {
    // 200 steps of one contact whose normal turns, whose overlap grows and shrinks and whose
    // tangential velocity makes it stick and slip in turn: fs, fn and the slip energy of
    // hertz_frictional, in Eigen's 3-vectors and in 4-lane registers, against apply_law's.
    ContactPhys p;
    p.model = ContactModel::HertzMindlin;
    p.kn = 2.9e9;  // K, N/m^1.5 (002's grains, R* = 2.5 mm)
    p.ks = 3.4e9;  // C, N/m^1.5
    p.tan_phi = 0.8;
    // Step k's geometry; vt: the amplitude of the tangential velocity (m/s).
    const auto step_geometry = [](int k, Real vt) {
      const Real a = 0.002 * k;
      ContactGeometry g;
      g.normal = Vec3(std::cos(a), std::sin(a), 0.1 * std::sin(3 * a)).normalized();
      g.overlap = 1e-5 * (1.5 + std::sin(0.05 * k));
      g.rel_vel = Vec3(-0.01, 0.02 * std::sin(0.1 * k), vt * std::cos(0.07 * k));
      g.angvel_sum = Vec3(3.0, -1.0, 2.0 * std::cos(0.02 * k));
      g.rel_angvel = Vec3::Zero();
      return g;
    };
    ContactState s_law;
    Vec3 fs_n = Vec3::Zero(), n_old = Vec3::Zero();
    V4 fs_w = V4{}, n_old_w = V4{};
    Real d_n = 0, d_w = 0;
    bool same = true, slipped = false, stuck = false;
    for (int k = 0; k < 200; ++k) {
      const ContactGeometry g = step_geometry(k, 0.3);
      const Real before = s_law.dissip_friction;
      const LawOutput out = apply_law(p, g, 1e-6, s_law);
      (s_law.dissip_friction > before ? slipped : stuck) = true;
      const Real fn_n = hertz_frictional<NarrowOps>(fs_n, n_old, g.normal, g.overlap,
                                                    g.rel_vel, g.angvel_sum, p.kn, p.ks,
                                                    p.tan_phi, 1e-6, d_n);
      n_old = g.normal;
      const V4 n_w = v4(g.normal);
      const Real fn_w = hertz_frictional<WideOps>(fs_w, n_old_w, n_w, g.overlap,
                                                  v4(g.rel_vel), v4(g.angvel_sum), p.kn, p.ks,
                                                  p.tan_phi, 1e-6, d_w);
      n_old_w = n_w;
      const Vec3 f_n = fn_n * g.normal + fs_n + Vec3::Zero();
      same = same && fn_n == s_law.fn && fn_w == s_law.fn && fs_n == s_law.fs &&
             vec3(fs_w) == s_law.fs && d_n == s_law.dissip_friction &&
             d_w == s_law.dissip_friction && f_n == out.force2 && out.moment2 == Vec3::Zero();
    }
    check(same && slipped && stuck,
          "Hertz short kernel == composed law over 200 steps (stick and slip, both forms), "
          "bitwise");
    // With dashpots (002's filling: 0.97 of critical, normal and shear; then normal only).
    for (const auto& [bn, bs] : {std::pair<Real, Real>{0.97, 0.97}, {0.3, 0.0}}) {
      ContactPhys q = p;
      q.beta_n = bn;
      q.beta_s = bs;
      q.mass_eff = 2.1e-4;  // kg
      ContactState st;
      Vec3 gs_n = Vec3::Zero(), m_old = Vec3::Zero();
      V4 gs_w = V4{}, m_old_w = V4{};
      Real df_n = 0, dv_n = 0, df_w = 0, dv_w = 0;
      bool eq = true, slip = false, stick = false;
      for (int k = 0; k < 200; ++k) {
        const ContactGeometry g = step_geometry(k, 3.0);
        const Real before = st.dissip_friction;
        const LawOutput out = apply_law(q, g, 1e-6, st);
        Vec3 fvs_n;
        const Real fn_n = hertz_damped<NarrowOps>(gs_n, m_old, g.normal, g.overlap, g.rel_vel,
                                                  g.angvel_sum, q, 1e-6, df_n, dv_n, fvs_n);
        m_old = g.normal;
        const V4 n_w = v4(g.normal);
        V4 fvs_w;
        const Real fn_w = hertz_damped<WideOps>(gs_w, m_old_w, n_w, g.overlap, v4(g.rel_vel),
                                                v4(g.angvel_sum), q, 1e-6, df_w, dv_w, fvs_w);
        m_old_w = n_w;
        // (slipping: with a shear dashpot its force is dropped, else slip energy is added)
        ((bs > 0 ? fvs_n == Vec3::Zero() : st.dissip_friction > before) ? slip : stick) = true;
        eq = eq && fn_n == st.fn && fn_w == st.fn && gs_n == st.fs && vec3(gs_w) == st.fs &&
             df_n == st.dissip_friction && df_w == st.dissip_friction &&
             dv_n == st.dissip_viscous && dv_w == st.dissip_viscous &&
             Vec3(fn_n * g.normal + gs_n + fvs_n) == out.force2 &&
             vec3(fn_w * n_w + gs_w + fvs_w) == out.force2;
      }
      check(eq && slip && stick && dv_n > 0,
            "Hertz damped kernel == composed law over 200 steps (beta_n " + std::to_string(bn) +
                ", beta_s " + std::to_string(bs) + "; stick and slip, both forms), bitwise");
    }
    check(pair_kernel(p) == kHertzKernel && !short_kernel_applies(p),
          "registry: a plain Hertz–Mindlin pair takes the Hertz kernel, walls the composed law");
    p.beta_n = 0.1;
    check(pair_kernel(p) == kHertzDampedKernel,
          "registry: a Hertz pair with a dashpot takes the damped Hertz kernel");
    p.kr = 1.0;
    check(pair_kernel(p) == kComposedKernel, "registry: Hertz rolling takes the composed law");
    p.model = ContactModel::Linear;
    p.kr = 0;
    check(pair_kernel(p) == kComposedKernel, "registry: a linear dashpot takes the composed law");
    p.beta_n = 0;
    check(pair_kernel(p) == kLinearKernel, "registry: a plain linear pair takes its kernel");
  }
  // ---- Hertz–Mindlin: stiffness and energy are consistent with the force ----------------
  {
    ContactPhys p;
    p.model = ContactModel::HertzMindlin;
    p.kn = 2e8;
    p.ks = 5e8;
    const Real d = 3e-5, h = 1e-9;
    const Real f = HertzMindlinElastic::normal_force(p, d);
    Real kn, ks;
    HertzMindlinElastic::stiffness(p, d, kn, ks);
    const Real dfdd = (HertzMindlinElastic::normal_force(p, d + h) -
                       HertzMindlinElastic::normal_force(p, d - h)) / (2 * h);
    check(close(kn, dfdd, 1e-6), "Hertz: k_n = dF/d delta", kn, dfdd);
    const Real dedd = (HertzMindlinElastic::normal_energy(p, d + h) -
                       HertzMindlinElastic::normal_energy(p, d - h)) / (2 * h);
    check(close(f, dedd, 1e-6), "Hertz: F = dE/d delta", f, dedd);
    check(close(ks, 5e8 * std::sqrt(d), 1e-15), "Mindlin: k_t = C sqrt(delta)", ks, 5e8 * std::sqrt(d));
  }
  // ---- mixing two materials: written in place, every field; the moduli remembered ----------
  {
    Material h1 = Material::of_law(ContactModel::HertzMindlin), h2 = h1, h3 = h1;
    h1.young = 70e9, h1.poisson = 0.25, h1.friction_angle = 0.61, h1.density = 2650;
    h1.rolling_stiffness = 0.3, h1.rolling_friction = 0.1;  // (kr and rolling_cap set)
    h2.young = 20e9, h2.poisson = 0.3, h2.friction_angle = 0.5, h2.density = 2000;
    h3.young = 5e9, h3.poisson = 0.45, h3.friction_angle = 0.4, h3.density = 1200;
    h3.damping_normal = 0.97, h3.damping_shear = 0.5;
    PairLaw linear_over;
    linear_over.model_set = true, linear_over.model = ContactModel::Linear;
    linear_over.kn = 1e6, linear_over.friction = 0.5;
    const auto same = [](const ContactPhys& x, const ContactPhys& y) {
      return std::memcmp(&x, &y, sizeof x) == 0;
    };
    ContactPhys out;
    std::memset(static_cast<void*>(&out), 0x7f, sizeof out);  // (a stale record: every field must be written)
    bool in_place = true, moduli = true;
    const Material* mats[] = {&h1, &h2, &h3};
    // The pairs in turn, so that the remembered moduli change at every call.
    for (int k = 0; k < 12; ++k) {
      const Material& a = *mats[k % 3];
      const Material& b = *mats[(k / 3) % 3];
      const Real r1 = 0.002 + 1e-4 * k, r2 = 0.003, m1 = 1e-4, m2 = 2e-4;
      const PairLaw* const laws[] = {nullptr, &linear_over};
      for (const PairLaw* law : laws) {
        mix_materials(a, b, r1, r2, m1, m2, law, out);
        in_place = in_place && same(out, mix_materials(a, b, r1, r2, m1, m2, law));
      }
      // Hertz's K = 4/3 E* sqrt(R*), E* from this pair's moduli (not the last pair's).
      const ContactPhys p = mix_materials(a, b, r1, r2, m1, m2);
      const Real e_star =
          1.0 / ((1 - a.poisson * a.poisson) / a.young + (1 - b.poisson * b.poisson) / b.young);
      moduli = moduli && p.kn == 4.0 / 3.0 * e_star * std::sqrt(r1 * r2 / (r1 + r2));
    }
    check(in_place, "mix: written in place over a stale record, the result returned, bitwise");
    check(moduli, "mix: the remembered moduli are the pair's, as the pairs change");
    const ContactPhys rolling = mix_materials(h1, h1, 0.002, 0.003, 1e-4, 2e-4);
    out = rolling;
    mix_materials(h2, h2, 0.002, 0.003, 1e-4, 2e-4, nullptr, out);
    check(rolling.kr > 0 && out.kr == 0 && out.rolling_cap == 0,
          "mix: a contact without rolling resistance over one with it has none");
  }
  // ---- registry -----------------------------------------------------------------------
  {
    bool round_trip = true;
    for (const LawInfo& l : kLaws) round_trip = round_trip && law_by_name(l.name) == l.id;
    check(round_trip, "registry: every law's name gives back its id");
    bool threw = false;
    try {
      law_by_name("hertz");
    } catch (const ParameterError& e) {
      threw = std::string(e.what()).find("'linear', 'hertz_mindlin'") != std::string::npos;
    }
    check(threw, "registry: an unknown name lists the known laws");
  }
  // ---- shape pairs ----------------------------------------------------------------------
  {
    Vec3 n, rel;
    Real li, lj;
    // i at rest at the origin, j at (0.019, 0, 0) moving -x at 1 m/s, radii 0.01: overlap
    // 1 mm, contact point in the middle.
    sphere_sphere_frame<NarrowOps>(Vec3(0.019, 0, 0), 0.019, 0.001, 0.01, 0.01, Vec3::Zero().eval(),
                                   Vec3(-1, 0, 0), Vec3::Zero().eval(), Vec3(0, 0, 10.0), n, li,
                                   lj, rel);
    check(n == Vec3(1, 0, 0) && li == 0.0095 && lj == 0.0095, "sphere-sphere: normal, branches");
    // j's surface point at -lj n moves with w x (-lj n) = 10 e_z x (-0.0095 e_x) = -0.095 e_y.
    check(close(rel[1], -0.095, 1e-14) && rel[0] == -1, "sphere-sphere: relative velocity",
          rel[1], -0.095);
    Wall w;
    w.axis = 2;
    w.sense = 1;
    w.position = 0;
    const ContactGeometry g = sphere_wall_geometry(w, Vec3(0, 0, 0.009), 0.01, Vec3(0, 0, -1),
                                                   Vec3::Zero(), 0.01 - wall_distance(w, Vec3(0, 0, 0.009)));
    check(close(g.overlap, 0.001, 1e-12) && g.normal == Vec3(0, 0, 1) &&
              close(g.branch2[2], -0.0095, 1e-12),
          "sphere-wall: overlap, normal, branch", g.overlap, 0.001);
    // Virtual sphere on a segment (000 eqs 13-19): grain above the middle of a link.
    const Real t = segment_parameter(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.25, 0, 0.005));
    check(t == 0.25, "sphere-cylinder: closest point parameter", t, 0.25);
    const ContactGeometry gv = virtual_sphere_geometry(Vec3(0.25, 0, 0.005), 0.005, Vec3::Zero(),
                                                       Vec3::Zero(), Vec3(0.25, 0, 0), 0.001,
                                                       Vec3::Zero(), Vec3::Zero());
    check(close(gv.overlap, 0.001, 1e-12) && gv.normal == Vec3(0, 0, 1),
          "sphere-cylinder: overlap through the virtual sphere", gv.overlap, 0.001);
    const Eigen::Vector3d bc = barycentric(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0),
                                           Vec3(0.2, 0.3, 0.01));
    check(close(bc[0], 0.5, 1e-14) && close(bc[1], 0.2, 1e-14) && close(bc[2], 0.3, 1e-14),
          "sphere-pfacet: barycentric weights (000 eqs 13-16)");
  }
  // ---- beam link (000 eqs 7-10): an axial bar, E A / L ----------------------------------
  {
    BeamParams bp;
    bp.young = 4e9;
    bp.radius = 1e-3;
    GridLink l;
    beam_stiffness(bp, 0.01, l);
    l.normal = Vec3(1, 0, 0);
    const Real stretch = 1e-6;
    beam_link_step(l, Vec3::Zero(), Vec3(0.01 + stretch, 0, 0), Vec3::Zero(), Vec3::Zero(),
                   Vec3::Zero(), Vec3::Zero(), 1e-6);
    const Real ea_l = 4e9 * M_PI * 1e-6 / 0.01;
    check(close(l.fn, ea_l * stretch, 1e-9), "beam: axial force E A / L x stretch", l.fn,
          ea_l * stretch);
    check(close(l.force_b[0], -ea_l * stretch, 1e-9), "beam: node b pulled back",
          l.force_b[0], -ea_l * stretch);
  }
  std::printf("%d passed, %d failed\n", passed, failed);
  return failed == 0 ? 0 : 1;
}
