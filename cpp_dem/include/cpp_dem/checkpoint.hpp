// Exact save and restore of the whole state of a scene (bodies, walls, contacts with their
// history, geogrid containers, broad-phase bookkeeping, parameters, energy accumulators,
// step, time) and of its controllers' state, as one binary blob. Restoring a blob and
// running n steps gives bitwise the same state as running on without the save.
// The HDF5 file around the blob is written in Python (cpp_dem/checkpoint.py).
#pragma once

#include <cstdint>
#include <vector>

#include "cpp_dem/scene.hpp"

namespace cpp_dem {

class Checkpoint {
 public:
  /// Format version of the blob; bumped when the layout changes.
  /// 2: pair contacts split hot / cold; 3: pair outputs grouped by j without i's torque,
  /// the bodies' storage order; 4: pair outputs padded to 4 doubles per vector; 5: the
  /// body store's arrays together (BodyStore::for_each_array); 6: clumps; 7: the periodic
  /// cell, pair contacts' image codes, bodies' image counters; 9: the shear kinematics
  /// (Scene::shear_kinematics); 10: density scaling (its parameters, and the bodies' and
  /// clumps' inertia factors); 11: the walls' openings (WallOpening). load also reads
  /// versions 8 (with the default kinematics), 9 (scaling off) and 10 (walls closed).
  static constexpr std::uint32_t kVersion = 11;
  /// The whole state of `scene` as bytes. Controllers are code, not data: the blob holds
  /// their count, `period`, `enabled` and, for StatefulController ones, their state.
  static std::vector<std::uint8_t> save(const Scene& scene);
  /// Restores a blob into `scene`, replacing all its state. The scene must hold the same
  /// controllers (same number, added in the same order, same kinds) as the saved one: a
  /// restart script rebuilds them and this restores their state. Throws ParameterError on a
  /// blob from another format or build (struct sizes differ) or a controller mismatch.
  static void load(Scene& scene, const std::vector<std::uint8_t>& blob);
};

}  // namespace cpp_dem
