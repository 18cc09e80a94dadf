// Sphere–wall contacts.
#pragma once

#include <vector>

#include "cpp_dem/laws/contact_law.hpp"

namespace cpp_dem {

/// A sphere–wall contact. Side 1 = the wall, side 2 = the sphere.
struct WallContact {
  int body = 0, wall = 0;
  bool active = false;
  /// Linear law without viscous damping and rolling resistance: the wall pass runs its
  /// short kernel (the same operations as apply_law).
  bool simple = false;
  std::uint8_t pad_[2] = {};    ///< zero (explicit padding: checkpoints are byte-identical)
  int phys_version = -1;
  ContactPhys phys;
  ContactState state;
  Vec3 force = Vec3::Zero();    ///< force on the sphere, N
  Vec3 torque = Vec3::Zero();   ///< torque on the sphere, N m
};

/// A build's sphere–wall candidates merged with the last build's contacts (WallContact, or any
/// contact record with `body` and `wall`, as MeshContact): add(b, w) for each candidate in
/// ascending (body, wall) order; a pair the old list (sorted the same way) holds keeps its
/// contact and history, a new one starts fresh, and `drop(contact)` is called for each old
/// contact not kept. finish() gives the new list.
template <class C, class Drop>
class WallContactMerge {
 public:
  WallContactMerge(const std::vector<C>& old, Drop drop) : old_(old), drop_(drop) {}
  /// Room for n contacts (the build's count of candidates).
  void reserve(std::size_t n) { next_.reserve(n); }
  void add(int b, int w) {
    while (k_ < old_.size() && (old_[k_].body < b || (old_[k_].body == b && old_[k_].wall < w)))
      drop_(old_[k_++]);
    if (k_ < old_.size() && old_[k_].body == b && old_[k_].wall == w) {
      next_.push_back(old_[k_++]);
    } else {
      C c;
      c.body = b;
      c.wall = w;
      next_.push_back(c);
    }
  }
  std::vector<C> finish() {
    for (; k_ < old_.size(); ++k_) drop_(old_[k_]);
    return std::move(next_);
  }

 private:
  const std::vector<C>& old_;
  Drop drop_;
  size_t k_ = 0;
  std::vector<C> next_;
};

/// The contacts of each of n bodies (CSR, in contact order, so reductions into bodies have a
/// fixed order): body b's are adj[off[b]] .. adj[off[b + 1] - 1].
template <class C>
void contacts_by_body(const std::vector<C>& contacts, int n, std::vector<int>& off,
                      std::vector<int>& adj) {
  off.assign(n + 1, 0);
  for (const auto& c : contacts) off[c.body + 1]++;
  for (int b = 0; b < n; ++b) off[b + 1] += off[b];
  adj.resize(off[n]);
  std::vector<int> fill(off.begin(), off.end() - 1);
  for (int c = 0; c < static_cast<int>(contacts.size()); ++c) adj[fill[contacts[c].body]++] = c;
}

}  // namespace cpp_dem
