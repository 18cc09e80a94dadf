// Sphere–sphere contacts: the hot record the pair pass reads and writes every step, its cold
// part, and the per-step output grouped by the second body.
#pragma once

#include <array>

#include "cpp_dem/bodies/cell.hpp"
#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// A sphere–sphere contact (candidate pair from the broad phase; active while overlapping):
/// the hot part, what the pair pass reads and writes every step (96 bytes). Its first body
/// is its candidate's row (Scene::pair_ioff_), and its parameters are those of the scene's
/// materials as of the last pair pass (Scene::pair_phys_version_). The friction
/// it dissipates is in a parallel array of doubles (Scene::pair_dissip_, written when it
/// slips). The rest of its parameters and history (PairContactCold) is in another parallel
/// array, which a scene has only once one of its material pairs takes a kernel that reads it
/// (dashpots, rolling resistance, the composed law): with the short kernels alone the hot
/// record holds all the law's parameters (Scene::ensure_pair_cold).
/// The full records: Scene::pair_phys(k), Scene::pair_state(k).
struct PairContact {
  int j = 0;                    ///< second body's slot (side 2; side 1, i < j, is its row)
  bool active = false;
  /// The pair pass's kernel (laws/registry.hpp's PairKernel): a linear or Hertz–Mindlin law
  /// without viscous damping and without rolling resistance takes its short kernel, which
  /// reads only this record (and adds slip energy to the cold part); a Hertz–Mindlin law
  /// with dashpots its damped kernel, which reads the cold part's phys too; 0: the composed
  /// law. (Checkpoints hold 0 or 1, the linear kernel's flag; the Hertz kernels are found
  /// again at the load.)
  std::uint8_t kernel = 0;
  /// The periodic image of j the contact sees (bodies/cell.hpp's image code; kNoShift: j).
  std::uint8_t image = kNoShift;
  /// The law's ContactModel (as its number; set with kn, ks, tan_phi): with them the whole
  /// phys of a short kernel's contact where the scene has no cold part (Scene::pair_phys).
  std::uint8_t model = 0;
  Real kn = 0;                  ///< copy of ContactPhys::kn
  Real ks = 0;                  ///< copy of ContactPhys::ks
  Real tan_phi = 0;             ///< copy of ContactPhys::tan_phi
  // (Each vector is followed by a scalar, so the pair pass loads and stores the pair as one
  // 4-double register; its batch reads kn, ks, tan_phi as one too: pair_batch.hpp.)
  Vec3 fs = Vec3::Zero();       ///< ContactState::fs, elastic shear force on j, N
  Real overlap = 0;             ///< ContactState::overlap, m
  Vec3 normal = Vec3::Zero();   ///< ContactState::normal (zero: new contact)
  Real fn = 0;                  ///< ContactState::fn, N
};

/// A sphere–sphere contact as a checkpoint holds it (formats up to this one): the hot record
/// with its first body and the scene phys version its phys was computed at (104 bytes).
struct PairContactDisk {
  int i = 0, j = 0;
  bool active = false;
  std::uint8_t kernel = 0;
  std::uint8_t image = kNoShift;
  std::uint8_t model = 0;
  int phys_version = -1;
  Real kn = 0;
  Real ks = 0;
  Real tan_phi = 0;
  Vec3 fs = Vec3::Zero();
  Real overlap = 0;
  Vec3 normal = Vec3::Zero();
  Real fn = 0;
};

/// The record of a candidate that has not touched (or touched and opened without slipping):
/// second body j, seen at its image, inactive, with zero springs and no parameters yet.
inline PairContact fresh_pair(int j, std::uint8_t image) {
  PairContact c;
  c.j = j;
  c.image = image;
  return c;
}

/// The fields the hot record and the checkpoint's share, from one to the other (all but
/// the bodies, the image and the phys version).
template <class From, class To>
void copy_pair_fields(const From& a, To& b) {
  b.active = a.active;
  b.kernel = a.kernel;
  b.model = a.model;
  b.kn = a.kn;
  b.ks = a.ks;
  b.tan_phi = a.tan_phi;
  b.fs = a.fs;
  b.overlap = a.overlap;
  b.normal = a.normal;
  b.fn = a.fn;
}

/// A checkpoint's record as the hot record (its first body and phys version aside).
inline PairContact hot_pair(const PairContactDisk& d) {
  PairContact c = fresh_pair(d.j, d.image);
  copy_pair_fields(d, c);
  return c;
}

/// The hot record c of first body i, its phys made at version phys_version, as a checkpoint
/// holds it.
inline PairContactDisk disk_pair(const PairContact& c, int i, int phys_version) {
  PairContactDisk d;
  d.i = i;
  d.j = c.j;
  d.image = c.image;
  d.phys_version = phys_version;
  copy_pair_fields(c, d);
  return d;
}

/// The cold part of a sphere–sphere contact (same index as its PairContact), in a scene
/// whose materials need it (PairContact).
struct PairContactCold {
  ContactPhys phys;
  Vec3 mr = Vec3::Zero();       ///< ContactState::mr, rolling moment on j, N m
  Real dissip_viscous = 0;      ///< ContactState::dissip_viscous, J
};

/// What a sphere–sphere contact gives its body j in the last step, kept apart from the
/// contact's history in a compact array grouped by j, so the reduction into bodies reads it
/// contiguously. Zero for an inactive contact.
/// (i's share is summed by the pair pass per body, Scene::pair_fi_ / pair_ti_.)
/// Each vector is followed by a zero double, so that the pair pass stores and the reduction
/// loads it as one 4-double register.
struct PairOutput {
  Vec3 force = Vec3::Zero();     ///< force on j (i gets -force), N
  Real pad_force = 0;            ///< zero (padding)
  Vec3 torque_j = Vec3::Zero();  ///< torque on j, N m
  Real pad_torque = 0;           ///< zero (padding)
};

/// A cross pair's shares in a threaded direct pass (Scene::pair_cross_): a contact whose
/// second body j another thread sums. Its shares are computed before the threads sum their
/// bodies, then added where the one-thread pass adds them: j's among j's first terms, i's in
/// its place in i's running sum, so the sums have the one-thread pass's bits.
struct PairCross {
  PairOutput out;                 ///< j's force and torque (PairOutput), N, N m
  std::array<Real, 4> fi{}, ti{};  ///< i's shares as the pass adds them (fourth zero), N, N m
  int i = 0, j = 0;               ///< the bodies (set with the index)
  int on = 0;                     ///< whether the contact gave shares in the last pass
};

}  // namespace cpp_dem
