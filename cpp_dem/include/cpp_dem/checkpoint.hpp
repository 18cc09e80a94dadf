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
  /// clumps' inertia factors); 11: the walls' openings (WallOpening); 12: each controller's
  /// kind (its C++ type); 13: materials by their field list (the law's name, then each
  /// parameter's name and stored value: a parameter added later takes its default); 14: the
  /// cylindrical and triangle-mesh walls and their contacts. load also reads versions 8 (with the default
  /// kinematics), 9 (scaling off), 10 (walls closed), 11 (controllers' kinds unchecked), 12
  /// (materials as records of the 8 parameters then) and 13 (no cylindrical walls).
  static constexpr std::uint32_t kVersion = 15;
  /// The whole state of `scene` as bytes. Controllers are code, not data: the blob holds
  /// their count, kinds, `period`, `enabled` and, for StatefulController ones, their state.
  static std::vector<std::uint8_t> save(const Scene& scene);
  /// Restores a blob into `scene`, replacing all its state; throws ParameterError, leaving
  /// `scene` as it was, on
  /// - a blob from another format or build (struct sizes differ), or a corrupt one;
  /// - stored values the API's setters refuse (materials, pair laws, dt and the other
  ///   parameters, the cell, walls and their openings, radii, masses, positions, clumps,
  ///   controller periods): each goes through its setter on a scratch scene;
  /// - other controllers: the scene must hold the same controllers (same number, added in
  ///   the same order, same kinds) as the saved one (a restart script rebuilds them and this
  ///   restores their state), whatever `replace` says;
  /// - unless `replace`, a blob of another scene: periodic or not (and which axes), body
  ///   count, each body's kind (sphere or grid node) and clump (free, or member of clump c),
  ///   clump count, wall count and each wall's axis and side. A blank scene (no bodies, no
  ///   walls, no periodic cell) takes any blob: it has nothing to replace.
  static void load(Scene& scene, const std::vector<std::uint8_t>& blob, bool replace = false);

 private:
  /// Refuses, with the setter's own message, a stored value of `t` the API would refuse
  /// (the setters run on a scratch scene; `t` is not changed).
  static void check_values(const Scene& t);
  /// Unless `s` is blank, refuses a restored scene `t` that is not the same scene as `s`
  /// (see load).
  static void check_same_scene(const Scene& s, const Scene& t);
};

}  // namespace cpp_dem
