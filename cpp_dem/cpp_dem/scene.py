"""The Python face of a DEM scene: typed helpers around the compiled `_core.Scene`."""

from __future__ import annotations

import difflib
import math
import os
import sys
import time as _time
from typing import Callable, Iterable, Sequence

import numpy as np

from cpp_dem import _core
from cpp_dem._core import Material, ParameterError
from cpp_dem.fixedorder import unit

#: Under automatic threads (``apply_threads(0)``), a scene with fewer bodies than this runs
#: on one thread: below it a step's parallel regions cost more than they save (measured with
#: ``bench/threads_auto.py``; docs/benchmarks.md).
AUTO_SERIAL_BODIES = 1000

#: What ``apply_threads(0)`` decided: whether the threads are automatic, the threads for a
#: scene of AUTO_SERIAL_BODIES bodies or more, and why (the line it printed).
_AUTO = {"on": False, "threads": 1, "note": ""}


def _cpu_ticks(cpus) -> dict:
    """{cpu: (busy ticks, all ticks)} of ``cpus`` from /proc/stat (busy: all but idle and
    iowait); {} where it cannot be read."""
    out = {}
    try:
        with open("/proc/stat") as fh:
            for line in fh:
                name, *vals = line.split()
                if not name.startswith("cpu") or name == "cpu":
                    continue
                k = int(name[3:])
                if k in cpus:
                    t = [int(v) for v in vals[:8]]
                    out[k] = (sum(t) - t[3] - t[4], sum(t))
    except (OSError, ValueError):
        return {}
    return out


def busy_cores(before: dict, after: dict, threshold: float = 0.5) -> int:
    """How many CPUs were busy between two ``_cpu_ticks`` samples: those whose busy share of
    the interval is above ``threshold`` (a CPU without ticks in it counts as free)."""
    busy = 0
    for k, (b1, t1) in after.items():
        b0, t0 = before.get(k, (b1, t1))
        if t1 > t0 and (b1 - b0) / (t1 - t0) > threshold:
            busy += 1
    return busy


def _quota_cores(path: str = "/sys/fs/cgroup/cpu.max") -> float | None:
    """The cgroup's CPU quota in cores ("200000 100000" -> 2.0), None without one."""
    try:
        quota, period = open(path).read().split()[:2]
    except (OSError, ValueError):
        return None
    return None if quota == "max" else int(quota) / int(period)


def free_cores(sample_s: float = 0.1) -> tuple[int, int]:
    """(the cores this process may use, how many of them other work keeps busy): the CPUs of
    its affinity (capped by a cgroup quota), and those whose busy share over ``sample_s``
    seconds of /proc/stat was above one half while this process slept."""
    cpus = set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else set(
        range(os.cpu_count() or 1))
    usable = len(cpus)
    quota = _quota_cores()
    if quota is not None:
        usable = max(1, min(usable, int(quota)))
    before = _cpu_ticks(cpus)
    _time.sleep(sample_s)
    busy = busy_cores(before, _cpu_ticks(cpus)) if before else 0
    return usable, min(busy, usable - 1)


def apply_threads(threads: int) -> str:
    """Sets this process's OpenMP threads the way every ``--threads`` option means it, and
    returns what it chose (one line). n > 0: n threads. 0: automatic: ``OMP_NUM_THREADS``
    where it is set; else a scene below :data:`AUTO_SERIAL_BODIES` bodies runs on one thread,
    and a larger one on the cores free of other work (:func:`free_cores`, sampled when the
    first such scene runs: an OpenMP thread on a core that another process keeps busy makes
    every parallel region wait for it; ``pullout-000 --smoke`` took 3.4 x as long on both
    cores of a 2-core machine with one busy as on one thread). Automatic threads that leave
    cores to other work say so on stderr. Results do not depend on the threads."""
    if threads > 0:
        set_num_threads(int(threads))
        _AUTO["note"] = f"{int(threads)} thread(s) (--threads {int(threads)})"
        return _AUTO["note"]
    if os.environ.get("OMP_NUM_THREADS"):
        _AUTO.update(on=False, note=f"{_core.get_num_threads()} thread(s) (OMP_NUM_THREADS)")
        return _AUTO["note"]
    _AUTO.update(on=True, threads=None,
                 note=f"automatic threads: one for a scene below {AUTO_SERIAL_BODIES} bodies, "
                      "else the cores free of other work (--threads N to choose)")
    _core.set_num_threads(1)  # (until a large scene runs: the work outside Scene.run too)
    return _AUTO["note"]


def _auto_threads(bodies: int) -> None:
    """Under automatic threads, the threads for a scene of ``bodies`` bodies (one below
    AUTO_SERIAL_BODIES; else the free cores, sampled once), set only when they change."""
    if not _AUTO["on"]:
        return
    if bodies < AUTO_SERIAL_BODIES:
        want = 1
    else:
        if _AUTO["threads"] is None:
            usable, busy = free_cores()
            _AUTO["threads"] = usable - busy
            _AUTO["note"] = (f"{usable - busy} thread(s) (automatic: {usable} core(s), {busy} "
                             "busy with other work; --threads N to choose)")
            if busy:
                print(f"[threads] {_AUTO['note']}", file=sys.stderr, flush=True)
        want = _AUTO["threads"]
    if want != _core.get_num_threads():
        _core.set_num_threads(want)


def set_num_threads(threads: int) -> None:
    """Sets the OpenMP threads of every scene to ``threads`` (>= 1): a choice, so automatic
    threads (``apply_threads(0)``) end."""
    _core.set_num_threads(int(threads))
    _AUTO["on"] = False


def threads_for(scene) -> int:
    """The OpenMP threads ``scene`` runs on (automatic threads: set for its size now, as
    ``Scene.run`` does), for a run's log."""
    _auto_threads(scene.num_bodies)
    return _core.get_num_threads()


_DOF_BITS = {"x": 1, "y": 2, "z": 4, "rx": 8, "ry": 16, "rz": 32}
#: The most steps one call of Scene.run takes (the core counts steps in a signed 64-bit integer).
_MAX_STEPS = 2**63 - 1

#: Wall order of :meth:`Scene.add_box`.
BOX_WALLS = ("x-", "x+", "y-", "y+", "z-", "z+")


def _check_parts(parts: dict, model: str) -> None:
    """The optional parameters a material helper passes on: the parameters of the law's field
    list that have a default (``cpp_dem.material_fields(model)``)."""
    optional = [f["name"] for f in _core.material_fields(model) if f["default"] is not None]
    for key, value in parts.items():
        if key not in optional:
            close = difflib.get_close_matches(key, optional, n=1)
            raise ParameterError(f"{key}={value!r}: not a parameter this helper passes on to a "
                                 f"'{model}' material; allowed: {', '.join(optional)}"
                                 + (f" (did you mean {close[0]}?)" if close else ""))
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ParameterError(f"{key}={value!r}: must be a number")


def linear_material(*, density: float, young: float, poisson: float,
                    friction_angle_deg: float, **parts: float) -> Material:
    """Material for the linear Cundall–Strack law (000 eqs 1–6). SI units (kg/m^3, Pa, deg).

    ``parts`` are the optional parameters (``cpp_dem.material_fields("linear")`` with a
    default): damping_normal, damping_shear (ratios of critical), rolling_stiffness,
    rolling_friction.
    """
    _check_parts(parts, "linear")
    return Material(model="linear", density=density, young=young, poisson=poisson,
                    friction_angle_deg=friction_angle_deg, **parts)


def hertz_mindlin_material(*, density: float, shear_modulus: float, poisson: float,
                           friction_coefficient: float, **parts: float) -> Material:
    """Hertz–Mindlin material from the parameters PFC uses (002 Table 1).

    shear_modulus: G, Pa; poisson: nu, -; friction_coefficient: mu = tan(phi), -;
    density: kg/m^3. Young's modulus is E = 2 G (1 + nu).
    """
    _check_parts(parts, "hertz_mindlin")
    for key, value, unit in (("density", density, "kg/m^3"), ("shear_modulus", shear_modulus, "Pa"),
                             ("poisson", poisson, "-"),
                             ("friction_coefficient", friction_coefficient, "-")):
        if isinstance(value, (bool, str, bytes)) or not isinstance(value, (int, float, np.number)):
            raise ParameterError(f"{key}={value!r}: must be a number ({unit})")
    if not (math.isfinite(poisson) and -1 < poisson <= 0.5):
        raise ParameterError(f"poisson={poisson}: must be in (-1, 0.5]")
    if not (friction_coefficient >= 0 and math.isfinite(friction_coefficient)):
        raise ParameterError(f"friction_coefficient={friction_coefficient}: must be >= 0")
    if not (shear_modulus > 0 and math.isfinite(shear_modulus)):
        raise ParameterError(f"shear_modulus={shear_modulus}: must be > 0 (Pa)")
    return Material(model="hertz_mindlin", density=density,
                    young=2.0 * shear_modulus * (1.0 + poisson), poisson=poisson,
                    friction_angle_deg=math.degrees(math.atan(friction_coefficient)), **parts)


def _numbers(values, field: str, unit: str) -> np.ndarray:
    """values as a float array, or ParameterError naming the field."""
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{field}={values!r}: must be numbers ({unit})") from None
    return a


def _index(value, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{field}={value!r}: must be a whole number (an index returned by "
                             "add_material)")
    if not 0 <= int(value) < 2**31:
        raise ParameterError(f"{field}={value}: no such material (an index returned by "
                             "add_material: 0, 1, ...)")
    return int(value)


def _ids(values, field: str, count: int, what: str) -> np.ndarray:
    """values (one id or several) as int ids in [0, count), or ParameterError naming the field:
    a float, a bool or an id out of range is refused (not truncated or wrapped)."""
    a = np.atleast_1d(np.asarray(values, dtype=object if np.ndim(values) == 0 else None))
    if a.size == 0 and a.ndim == 1:
        return np.zeros(0, np.int64)
    if a.dtype == object:
        ok = all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
                 for v in a.ravel())
    else:
        ok = np.issubdtype(a.dtype, np.integer)
    if not ok or a.ndim != 1:
        raise ParameterError(f"{field}={values!r}: must be {what} ids, whole numbers (not "
                             "floats or booleans), one or a 1-D list")
    a = a.astype(np.int64)
    bad = (a < 0) | (a >= count)
    if bad.any():
        raise ParameterError(f"{field}: {what} {int(a[np.argmax(bad)])} does not exist (the "
                             f"scene has {count}: 0 to {count - 1})")
    return a


def _behind_cylinder(cyl: dict, x: np.ndarray) -> np.ndarray:
    """(n,) whether each centre x (n, 3), m, lies behind the cylindrical wall ``cyl``
    (``Scene.cylinder_wall``): within its ends and beyond its lateral surface, on the side its
    spheres are not (outside an ``inside`` one, inside an outer one). Such a centre is never
    touched by it."""
    d = x - np.asarray(cyl["centre"])
    a = np.asarray(cyl["axis"])
    t = d @ a
    rho = np.linalg.norm(d - np.outer(t, a), axis=1)
    tol = 1e-9 * cyl["radius"]
    within = (t >= cyl["lo"]) & (t <= cyl["hi"])
    beyond = rho > cyl["radius"] + tol if cyl["inside"] else rho < cyl["radius"] - tol
    return within & beyond


def _dof_mask(dofs: str) -> int:
    mask = 0
    for w in dofs.replace(",", " ").split():
        if w == "all":
            mask |= 63
        elif w == "xyz":
            mask |= 7
        elif w == "rot":
            mask |= 56
        elif w in _DOF_BITS:
            mask |= _DOF_BITS[w]
        else:
            raise ParameterError(f"dofs='{dofs}': unknown DOF '{w}'; allowed: x y z rx ry rz "
                                 "xyz rot all")
    return mask


def _quat_mul(a, b) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _quat_from_matrix(m) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    m = np.asarray(m, dtype=float)
    t = np.trace(m)
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    return unit(q)


class ControllerLimitWarning(UserWarning):
    """A stress-controlled wall drifted from its target at its speed cap during a run (the
    message names the controller, axis or wall, target, reached stress and cap). Make it an
    error with ``warnings.simplefilter("error", cpp_dem.ControllerLimitWarning)`` or
    ``scene.strict_controllers = True``."""


class ServoTargetWarning(ControllerLimitWarning):
    """A ControllerLimitWarning: a servo of one wall (ServoWall, CylinderServo, MeshServo)
    ended a run without its stress within 5 % of its target at any call since the target
    was set (once per target). A loop of short runs that judges its own convergence filters
    it (``warnings.simplefilter("ignore", cpp_dem.ServoTargetWarning)``), keeping the
    warning of a wall that drifts at its cap."""


class TargetNotMetWarning(UserWarning):
    """A preparation ended away from a target it was given (e.g. a porosity the sample was
    already denser than): the message names the target, what was reached and why. Make it an
    error with ``warnings.simplefilter("error", cpp_dem.TargetNotMetWarning)``."""


class PhysicalRangeWarning(UserWarning):
    """A material or a grain with values no grain has (``Scene.add_material``,
    ``Scene.add_clumps``; bounds in :data:`GRAIN_BOUNDS`): the run goes on, but says so. A
    value given on purpose (a contact that never slides, at 89 deg) is one to filter:
    ``warnings.simplefilter("ignore", cpp_dem.PhysicalRangeWarning)``."""


#: What no grain has, and why (docs/reliability.md):
#: - ``young``: no solid is stiffer than diamond, 1.05-1.2e12 Pa;
#: - ``density``: none is denser than osmium, 22 590 kg/m^3;
#: - ``friction_angle_deg``: friction measured between grains of sand, gravel and rock, and
#:   against steel or a geogrid, is mu 0.1-1.0 (6-45 deg); above 60 deg (mu 1.73) a contact is
#:   one that does not slide, not a material's;
#: - ``clump_members``: a grain's shape as a clump takes 2-100 spheres (the studies here
#:   6-24: docs/clumps.md); each member is a sphere to every contact search, so a clump of
#:   more than 1000 costs as much as 1000 grains.
GRAIN_BOUNDS = {"young": 1.2e12, "density": 2.3e4, "friction_angle_deg": 60.0,
                "clump_members": 1000}


def _warn_range(msg: str) -> None:
    import warnings

    warnings.warn(msg, PhysicalRangeWarning, stacklevel=3)


class TimeStepWarning(UserWarning):
    """A hand-set time step above ``critical_dt()`` at a moment the dt check does not stop
    (:meth:`Scene.run`; docs/reliability.md)."""


class Scene(_core.Scene):
    """A DEM scene: spheres, walls, materials, contacts and the step loop (in C++).

    Parameters
    ----------
    gravity : gravitational acceleration, m/s^2 (3 values).
    dt : time step, s (or use :meth:`set_auto_timestep`).
    local_damping : Cundall local damping coefficient, -.
    """

    def __init__(self, *, gravity: Sequence[float] = (0.0, 0.0, 0.0), dt: float | None = None,
                 local_damping: float = 0.0) -> None:
        super().__init__()
        self.gravity = np.asarray(gravity, dtype=float)
        if dt is not None:
            self.dt = dt
        self.local_damping = local_damping

    # ---- building ------------------------------------------------------------------------
    def add_material(self, material) -> int:
        """Adds ``material`` (a ``cpp_dem.Material``); returns its index. A modulus, a
        density or a friction angle that no grain has (:data:`GRAIN_BOUNDS`: E 5e16 Pa,
        mu 20, phi 89.9 deg) gives a :class:`PhysicalRangeWarning` naming the value and the
        bound."""
        idx = _core.Scene.add_material(self, material)
        b = GRAIN_BOUNDS
        for field, value, bound, unit, why in (
                ("young", material.young, b["young"], "Pa", "no solid is stiffer than diamond"),
                ("density", material.density, b["density"], "kg/m^3",
                 "no solid is denser than osmium"),
                ("friction_angle_deg", material.friction_angle_deg, b["friction_angle_deg"],
                 "deg", "grains of sand, gravel and rock, steel and geogrids have mu 0.1-1.0, "
                        "6-45 deg; such a contact does not slide")):
            if value > bound:
                extra = (f" (mu = tan phi = {math.tan(math.radians(value)):.3g})"
                         if field == "friction_angle_deg" else "")
                _warn_range(f"material {idx}: {field}={value:g}{extra} is above {bound:g} "
                            f"{unit}, which no grain has ({why}); the run goes on with it "
                            "(filter cpp_dem.PhysicalRangeWarning if it is meant)")
        return idx

    def set_pair_law(self, a: int, b: int, **law) -> None:
        """Gives materials a and b their own law over the mixing rules (``_core.Scene.
        set_pair_law``: model, kn, ks, friction, damping_normal, damping_shear; None keeps the
        mixed value). A friction coefficient above tan 60 deg (:data:`GRAIN_BOUNDS`) gives a
        :class:`PhysicalRangeWarning`, as a material's friction angle does."""
        _core.Scene.set_pair_law(self, a, b, **law)
        mu = law.get("friction")
        bound = math.tan(math.radians(GRAIN_BOUNDS["friction_angle_deg"]))
        if mu is not None and mu > bound:
            _warn_range(f"set_pair_law({a}, {b}): friction={mu:g} is above {bound:.3g} (tan "
                        f"{GRAIN_BOUNDS['friction_angle_deg']:g} deg), which no grain has "
                        "(grains of sand, gravel and rock, steel and geogrids have mu 0.1-1.0); "
                        "such a contact does not slide; the run goes on with it (filter "
                        "cpp_dem.PhysicalRangeWarning if it is meant)")

    def add_spheres(self, centers, radii, *, material: int) -> np.ndarray:
        """Adds spheres with centres (n, 3) in m and radii (n,) in m; returns their ids.

        A sphere whose centre lies behind a wall of the scene (outside the box) is refused:
        the one-sided wall would never touch it."""
        c = _numbers(centers, "centers", "m")
        r = np.atleast_1d(_numbers(radii, "radii", "m"))
        c = np.atleast_2d(c)
        if c.ndim != 2 or c.shape[1] != 3:
            raise ParameterError(f"centers: shape {np.shape(centers)}; must be (n, 3) centres, m "
                                 "(or 3 numbers for one sphere)")
        if r.ndim != 1:
            raise ParameterError(f"radii: shape {np.shape(radii)}; must be (n,) radii, m")
        material = _index(material, "material")
        if self.num_walls and len(c) and c.shape[-1] == 3:
            pos = np.asarray(self.wall_positions)
            axes, senses = np.asarray(self.wall_axes), np.asarray(self.wall_senses)
            for w in range(self.num_walls):
                axis, sense = int(axes[w]), int(senses[w])
                behind = sense * (c[:, axis] - pos[w]) < 0
                if np.any(behind):
                    k = int(np.flatnonzero(behind)[0])
                    raise ParameterError(
                        f"centers[{k}]={c[k].tolist()}: behind wall {w} ({'xyz'[axis]} "
                        f"{'>=' if sense > 0 else '<='} {pos[w]:g} m is inside), outside the "
                        "walls; move it inside or add the walls after the spheres")
        if self.num_cylinder_walls and len(c) and c.shape[-1] == 3:
            for w in range(self.num_cylinder_walls):
                cyl = self.cylinder_wall(w)
                behind = _behind_cylinder(cyl, c)
                if np.any(behind):
                    k = int(np.flatnonzero(behind)[0])
                    side = "outside" if cyl["inside"] else "inside"
                    raise ParameterError(
                        f"centers[{k}]={c[k].tolist()}: {side} cylindrical wall {w}, behind "
                        "it; move it to the wall's side or add the wall after the spheres")
        first = self._add_spheres(c, r, material)
        return np.arange(first, first + len(r))


    def add_cylinder_wall(self, *, centre, axis, radius: float, inside: bool, material: int,
                          lo: float = -math.inf, hi: float = math.inf) -> int:
        """Adds a cylindrical wall (``_core.Scene.add_cylinder_wall``): its axis through
        ``centre`` (m) along ``axis``, ``radius`` (m), the spheres ``inside`` it (True: a
        triaxial cell's rigid side) or outside it (False: a pile), its lateral surface from
        ``lo`` to ``hi`` (m along the axis from the centre; default infinite). Returns its
        index."""
        if not isinstance(inside, (bool, np.bool_)):
            raise ParameterError(f"inside={inside!r}: must be True (the spheres inside the "
                                 "cylinder) or False (outside it)")
        return _core.Scene.add_cylinder_wall(self, centre=centre, axis=axis, radius=radius,
                                             inside=bool(inside),
                                             material=_index(material, "material"), lo=lo,
                                             hi=hi)

    def add_mesh_wall(self, vertices=None, triangles=None, *, material: int, path=None,
                      scale: float = 1.0, closed: bool = False) -> int:
        """Adds a rigid triangle-mesh wall; returns its index.

        Give ``vertices`` (n, 3), m, and ``triangles`` (m, 3) vertex indices, or ``path``: an
        STL, OBJ or PLY file (``scale`` turns its unit into m, 1e-3 for mm; read by
        :func:`cpp_dem.build.clump_mesh.read_triangle_mesh`, duplicate vertices merged so that
        neighbouring triangles share edges). The mesh may be open or closed and is two-sided.
        A sphere meets it at faces, edges and vertices, each once (docs/core.md, "Mesh
        walls"). ``set_mesh_velocity`` moves it; ``mesh_wall(k)`` gives its force and moment.

        ``closed=True`` where the mesh must bound a volume (a container the grains fill, a
        solid footing or clamp): it is refused, naming the first bad edge or pair of
        triangles, if it is open (an edge of one triangle: a hole), has an edge of three
        triangles or more, is not consistently oriented, or crosses itself
        (:func:`cpp_dem.build.clump_mesh.check_closed_mesh`). Vertices given twice at one place
        are two vertices there (a file's are merged when it is read).
        """
        if path is not None:
            if vertices is not None or triangles is not None:
                raise ParameterError("add_mesh_wall: give vertices and triangles, or path, not "
                                     "both")
            from cpp_dem.build.clump_mesh import read_triangle_mesh

            vertices, triangles = read_triangle_mesh(path, scale)
        elif vertices is None or triangles is None:
            raise ParameterError("add_mesh_wall: give vertices (n, 3, m) and triangles (m, 3), "
                                 "or path (an STL, OBJ or PLY file)")
        v = np.atleast_2d(_numbers(vertices, "vertices", "m"))
        t = np.asarray(triangles)
        if t.ndim != 2 or t.shape[1] != 3 or not (np.issubdtype(t.dtype, np.integer)
                                                   or np.all(np.mod(t, 1) == 0)):
            raise ParameterError(f"triangles: shape {t.shape}; must be (m, 3) vertex indices")
        t = t.astype(np.int64)
        out = (t < 0) | (t >= len(v))
        if out.any():
            k = int(np.argmax(out.any(axis=1)))
            i = int(t[k][out[k]][0])
            raise ParameterError(f"triangles[{k}]: vertex {i} is not one of the {len(v)} "
                                 "vertices")
        if not isinstance(closed, (bool, np.bool_)):
            raise ParameterError(f"closed={closed!r}: must be True or False")
        # (bad indices and degenerate triangles are refused below, by the core, by name)
        if closed and t.size and 0 <= t.min() and t.max() < len(v) and not (
                (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])).any():
            from cpp_dem.build.clump_mesh import check_closed_mesh

            try:
                check_closed_mesh(v, t)
            except ParameterError as e:
                raise ParameterError(f"add_mesh_wall(closed=True): {e}") from None
        return self._add_mesh_wall(v, t, _index(material, "material"))

    def add_box(self, lo: Sequence[float], hi: Sequence[float], *, material: int) -> list[int]:
        """Adds the six walls of the box [lo, hi] (m), facing inwards.

        Returns the wall ids in the order x-, x+, y-, y+, z-, z+ (see ``BOX_WALLS``).
        """
        lo_a = np.asarray(lo, dtype=float)
        hi_a = np.asarray(hi, dtype=float)
        if lo_a.shape != (3,) or hi_a.shape != (3,):
            raise ParameterError("lo, hi: expected 3 values each (m)")
        for a in range(3):
            if not hi_a[a] > lo_a[a]:
                raise ParameterError(f"hi[{a}]={hi_a[a]}: must be > lo[{a}]={lo_a[a]} (m)")
        if self.num_walls:
            # One-sided walls: the box's walls would bound sides that walls bound already (a
            # second box, or a box over a floor), and grains between two walls of one side
            # are behind one of them.
            axis, sense = int(self.wall_axes[0]), int(self.wall_senses[0])
            name = BOX_WALLS[2 * axis + (0 if sense > 0 else 1)]
            raise ParameterError(
                f"add_box(lo={lo_a.tolist()}, hi={hi_a.tolist()}): the scene has walls "
                f"already (wall 0, {name} at {float(self.wall_positions[0]):g} m); a box is "
                "added once, to a scene without walls (move a wall with set_wall_position)")
        ids = []
        for a in range(3):
            ids.append(self.add_wall(axis=a, position=float(lo_a[a]), sense=+1, material=material))
            ids.append(self.add_wall(axis=a, position=float(hi_a[a]), sense=-1, material=material))
        return ids

    def block_dofs(self, bodies: Iterable[int] | int, dofs: str) -> None:
        """Blocks DOFs of bodies: ``dofs`` is a space-separated subset of 'x y z rx ry rz'
        (or 'xyz', 'all', '' to free). A blocked DOF keeps its (possibly imposed) velocity.
        A clump's members cannot be blocked one by one: see :meth:`block_clump_dofs`."""
        mask = _dof_mask(dofs)
        for b in _ids(bodies, "bodies", self.num_bodies, "body"):
            self._set_blocked(int(b), mask)

    # ---- clumps ----------------------------------------------------------------------------
    def add_clumps(self, template, positions, orientations=None, *, material: int,
                   scale=1.0, stiffness: str = "member") -> np.ndarray:
        """Adds rigid clumps, copies of a :class:`cpp_dem.build.clumps.ClumpTemplate`.

        positions: (n, 3) centres of mass, m. orientations: (n, 4) unit quaternions (w, x, y,
        z) turning the template frame into the global one (None: all identity; see
        :func:`cpp_dem.build.clumps.random_orientations`). scale: one factor or n factors (> 0)
        scaling the template about its centre of mass. The mass and inertia are the union's
        (template.props) times the material's density. Returns the clump indices; the
        members' body ids are ``clump_members(c)``.

        stiffness: which radius the members' contacts take in the contact law's stiffness
        (and mixing rules): "member" (each member's own, as Yade, PFC's deformability method
        and LIGGGHTS) or "grain" (the clump's equivalent-volume radius: the grain is as stiff
        as its equivalent sphere whatever the number of members, so a small member at a
        grain's corner does not sink deep into what it touches).
        """
        from cpp_dem.build.clumps import ClumpTemplate

        if not isinstance(template, ClumpTemplate):
            raise ParameterError(f"template={type(template).__name__}: must be a ClumpTemplate "
                                 "(cpp_dem.build.clumps.ClumpTemplate.from_spheres)")
        x = np.atleast_2d(_numbers(positions, "positions", "m"))
        if x.shape[1] != 3:
            raise ParameterError(f"positions: shape {x.shape}; must be (n, 3) centres of mass, m")
        bad = ~np.isfinite(x).all(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            raise ParameterError(f"positions[{k}]={x[k].tolist()}: must be 3 finite numbers (m, "
                                 "the clump's centre of mass)")
        n = len(x)
        if orientations is None:
            q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        else:
            q = np.atleast_2d(np.asarray(orientations, dtype=float))
            if q.shape != (n, 4):
                raise ParameterError(f"orientations: shape {q.shape}; must be ({n}, 4) "
                                     "quaternions (w, x, y, z)")
            norm = np.linalg.norm(q, axis=1)
            bad = ~(np.abs(norm - 1) < 1e-6)
            if bad.any():
                k = int(np.argmax(bad))
                raise ParameterError(f"orientations[{k}]: norm {norm[k]!r}; must be a unit quaternion")
        f = _numbers(scale, "scale", "-")
        if f.shape not in ((), (1,), (n,)):
            raise ParameterError(f"scale: {f.size} factors for {n} clumps; give one factor or "
                                 f"one per clump ({n})")
        f = np.broadcast_to(f, (n,))
        if not np.all(np.isfinite(f) & (f > 0)):
            raise ParameterError(f"scale={scale!r}: must be > 0 (one factor or one per clump)")
        if stiffness not in ("member", "grain"):
            raise ParameterError(f"stiffness={stiffness!r}: must be 'member' or 'grain'")
        material = _index(material, "material")
        if template.num_members > GRAIN_BOUNDS["clump_members"]:
            _warn_range(f"template {template.name!r}: {template.num_members} members, more than "
                        f"{GRAIN_BOUNDS['clump_members']}: a grain's shape as a clump takes "
                        "2-100 spheres (the studies here 6-24), and each member is a sphere to "
                        f"every contact search, so each of these {n} clumps costs as much as "
                        f"{template.num_members} grains (filter cpp_dem.PhysicalRangeWarning "
                        "if it is meant)")
        rho = self.material(material).density
        props = template.props
        local = template.local_centres
        q_axes = _quat_from_matrix(props.axes)
        out = np.empty(n, dtype=int)
        for k in range(n):
            fk = float(f[k])
            qc = _quat_mul(unit(q[k]), q_axes)  # (fixedorder: not BLAS)
            if template.num_members == 1:
                # Exact, with the same arithmetic as a sphere of the scaled radius.
                r = float(template.radii[0]) * fk
                m = rho * 4.0 / 3.0 * math.pi * r * r * r
                inertia = np.full(3, 0.4 * m * r * r)
            else:
                m = rho * props.volume * fk ** 3
                inertia = rho * props.principal * fk ** 5
            rs = 0.5 * template.equivalent_diameter * fk if stiffness == "grain" else 0.0
            out[k] = self._add_clump(local * fk, template.radii * fk, material, m, inertia,
                                     x[k], qc, rs)
        return out

    def block_clump_dofs(self, clumps: Iterable[int] | int, dofs: str) -> None:
        """Blocks DOFs of clumps (as :meth:`block_dofs`; rotations about the global axes)."""
        mask = _dof_mask(dofs)
        for c in _ids(clumps, "clumps", self.num_clumps, "clump"):
            self._set_clump_blocked(int(c), mask)

    def clump_blocked_dofs(self, clump: int) -> str:
        """The blocked DOFs of a clump as a string like 'x y rz'."""
        mask = self._clump_blocked[int(_ids(clump, "clump", self.num_clumps, "clump")[0])]
        return " ".join(k for k, bit in _DOF_BITS.items() if mask & bit)

    def blocked_dofs(self, body: int) -> str:
        """The blocked DOFs of a body as a string like 'x y rz'."""
        mask = self._blocked[int(_ids(body, "body", self.num_bodies, "body")[0])]
        return " ".join(k for k, bit in _DOF_BITS.items() if mask & bit)

    # ---- geometry against the walls ---------------------------------------------------------
    @property
    def positions(self):
        """Body centres, m, shape (n, 3) (by id). Setting them is checked against the walls
        at the next run."""
        return _core.Scene.positions.fget(self)

    @positions.setter
    def positions(self, value) -> None:
        _core.Scene.positions.fset(self, value)
        self._geometry_changed()

    def _geometry_changed(self) -> None:
        self.__dict__["_geometry_version"] = self.__dict__.get("_geometry_version", 0) + 1

    def set_wall_position(self, wall: int, position: float) -> None:
        """Moves the plane wall ``wall`` to ``position`` (m) at once; checked against the
        bodies at the next run (a body left behind the wall is refused by name)."""
        _core.Scene.set_wall_position(self, wall, position)
        self._geometry_changed()

    def set_cylinder_radius(self, cylinder: int, radius: float) -> None:
        """Sets the cylindrical wall's radius (m) at once; checked against the bodies at the
        next run (a body left behind it is refused by name)."""
        _core.Scene.set_cylinder_radius(self, cylinder, radius)
        self._geometry_changed()

    def _check_geometry(self) -> None:
        """Before the first step, and at the first run after bodies or walls were added or
        positions set: every body's centre (spheres, clump members, and before the first
        step geogrid nodes) must be on the inner side of every wall but an opened one
        (one pass over the bodies; what is beyond an opened wall left through it). A body
        behind a wall is never touched by it (the walls are one-sided): ParameterError
        naming the body, its position and the wall."""
        key = (self.num_bodies, self.num_walls, self.num_cylinder_walls,
               self.__dict__.get("_geometry_version", 0))
        if self.__dict__.get("_geometry_checked") == key and self.step_count > 0:
            return
        self.__dict__["_geometry_checked"] = key
        if not ((self.num_walls or self.num_cylinder_walls) and self.num_bodies):
            return
        x = np.asarray(self.positions)
        pos = np.asarray(self.wall_positions)
        axes, senses = list(self.wall_axes), list(self.wall_senses)
        # After the first step a geogrid may have left the box legitimately (pulled out
        # through the front wall, then saved and loaded): its nodes are checked at step 0.
        check = (np.ones(len(x), bool) if self.step_count == 0
                 else np.asarray(self.body_kinds) != 1)
        for w in range(self.num_walls):
            if self.wall_opening(w)[0] >= 0:
                continue  # an opened wall: what is beyond it left through it (set_wall_opening)
            axis, sense = int(axes[w]), int(senses[w])
            tol = 1e-12 + 1e-9 * abs(float(pos[w]))
            behind = check & (sense * (x[:, axis] - pos[w]) < -tol)
            if not behind.any():
                continue
            k = int(np.flatnonzero(behind)[0])
            kind = "geogrid node" if int(self.body_kinds[k]) == 1 else "sphere"
            clump = int(np.asarray(self.clump_ids)[k]) if self.num_clumps else -1
            if clump >= 0:
                kind = f"member of clump {clump}"
            self.__dict__["_geometry_checked"] = None  # refused: check again next time
            raise ParameterError(
                f"body {k} ({kind}) at [{', '.join(f'{v:.6g}' for v in x[k])}] m: behind "
                f"wall {w} ({'xyz'[axis]} "
                f"{'>=' if sense > 0 else '<='} {pos[w]:g} m is inside), outside the walls "
                f"({int(behind.sum())} of the bodies); the wall would never touch it: move it "
                "inside, or build the walls around it")
        for w in range(self.num_cylinder_walls):
            cyl = self.cylinder_wall(w)
            behind = check & _behind_cylinder(cyl, x)
            if not behind.any():
                continue
            k = int(np.flatnonzero(behind)[0])
            self.__dict__["_geometry_checked"] = None  # refused: check again next time
            raise ParameterError(
                f"body {k} at [{', '.join(f'{v:.6g}' for v in x[k])}] m: "
                f"{'outside' if cyl['inside'] else 'inside'} cylindrical wall {w} (radius "
                f"{cyl['radius']:g} m; {int(behind.sum())} of the bodies), behind it: the wall "
                "would never touch it; move it to the wall's side")

    # ---- running ---------------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Time step, s. Set by hand, it is checked at the next ``run`` against
        ``critical_dt()`` (:meth:`_check_time_step`) besides the core's dt check."""
        return _core.Scene.dt.fget(self)

    @dt.setter
    def dt(self, value: float) -> None:
        _core.Scene.dt.fset(self, value)
        self._dt_by_hand = True

    def set_auto_timestep(self, safety: float = 0.8, period: int = 100) -> None:
        """Every ``period`` steps set dt = safety x critical_dt() (period 0: once, now)."""
        _core.Scene.set_auto_timestep(self, safety, period)
        self._dt_by_hand = period == 0

    def _check_time_step(self) -> None:
        """Says (TimeStepWarning, once per scene) that ``dt`` is above ``critical_dt()`` where
        the dt check cannot: when no contact is active, ``critical_dt()`` is the p-wave
        estimate R sqrt(rho / E), while the check holds dt to the estimate of the contacts
        that form, sqrt(2 m / k_n) with k_n >= E R for a grain: 2.9 times larger for spheres.
        A step between the two runs on without an error, and grains dropped on each other
        at 1.5 x the p-wave estimate (0.52 x the contacts') had their energy balance off by
        2-48 % (docs/reliability.md)."""
        dt = self.dt
        # (only a step set by hand, checked once per value: counting the contacts is a pass
        # over them, which a loop of short runs should not pay every call)
        if (not getattr(self, "_dt_by_hand", False) or getattr(self, "_dt_said", False)
                or getattr(self, "_dt_checked", None) == dt or self.dt_check_period <= 0
                or self.density_scaling or not self.num_bodies):
            return
        self._dt_checked = dt
        if self.num_active_contacts:
            return
        est = float(self.critical_dt())
        if not (math.isfinite(est) and est > 0 and dt > est * (1 + 1e-9)):
            return
        import warnings

        self._dt_said = True
        warnings.warn(TimeStepWarning(
            f"dt={dt:.4g} s is {dt / est:.3g} x critical_dt()={est:.4g} s, the "
            "p-wave estimate R sqrt(rho / E) of a scene in which no contact is active: once "
            "grains touch, the dt check holds dt only to their contacts' estimate, sqrt(2 m / "
            "k_n) (about 2.9 x the p-wave one for spheres), so the run goes on, but grains "
            "that strike each other then take only a few steps per impact (grains dropped on "
            "each other at 1.5 x the p-wave estimate: the energy balance 2-48 % off); lower "
            "dt, or use set_auto_timestep(safety <= 1)"), stacklevel=3)

    #: Raise ControllerLimitWarning as an error (see :meth:`_check_controller_limits`).
    strict_controllers: bool = False

    def _check_controller_limits(self, end: bool = True) -> None:
        """Says which stress-controlled walls drifted from their targets at their speed caps
        during the steps just run (ControllerLimitWarning; an error with
        ``strict_controllers``); the watch then starts again. At the ``end`` of a run, also
        which ServoWall has not reached its target at all (once per target)."""
        import warnings

        for i in range(self.num_controllers()):
            c = self.controller(i)
            if end and hasattr(c, "target_report"):
                for r in c.target_report():
                    at_cap = r["calls_at_cap"] == r["calls"]
                    why = (f"it ran at its speed cap {r['cap_m_per_s']:.4g} m/s for all "
                           f"{r['calls']} calls: raise its max_speed or run longer" if at_cap
                           else f"at its speed cap for {r['calls_at_cap']} of {r['calls']} "
                           "calls: run longer, raise its gain or max_speed, or check that "
                           "grains are in front of the wall")
                    wall = (f"cylindrical wall {r['cylinder']}" if "cylinder" in r
                            else f"mesh wall {r['mesh']}" if "mesh" in r
                            else f"wall {r['wall']}")
                    msg = (f"controller {i} ({type(c).__name__}, {wall}): has not "
                           f"reached its target {r['target_pa']:.6g} Pa (within 5 %) in this "
                           f"run; the stress is {r['reached_pa']:.6g} Pa; {why}")
                    c.clear_target_report(True)
                    if self.strict_controllers:
                        raise RuntimeError(msg)
                    warnings.warn(ServoTargetWarning(msg), stacklevel=3)
                c.clear_target_report(False)
            if not hasattr(c, "limit_report"):
                continue
            rows = c.limit_report()
            if not rows:
                continue
            c.clear_limit_report()
            for r in rows:
                if "component" in r:  # CellController: a component of the velocity gradient
                    where, knob = f"component {r['component']}", "max_rate"
                    cap = f"rate cap {r['cap_per_s']:.4g} 1/s"
                else:
                    where = (f"axis {r['axis']}, wall {r['wall']}" if "axis" in r
                             else f"cylindrical wall {r['cylinder']}" if "cylinder" in r
                             else f"mesh wall {r['mesh']}" if "mesh" in r
                             else f"wall {r['wall']}")
                    knob, cap = "max_speed", f"speed cap {r['cap_m_per_s']:.4g} m/s"
                msg = (f"controller {i} ({type(c).__name__}, {where}): at its {cap} for "
                       f"{r['calls']} calls while the stress drifted from the target "
                       f"{r['target_pa']:.6g} Pa to {r['reached_pa']:.6g} Pa; raise its {knob} "
                       "or slow the loading")
                if self.strict_controllers:
                    raise RuntimeError(msg)
                warnings.warn(ControllerLimitWarning(msg), stacklevel=3)
    def run(self, steps: int, *, every: int = 0, callback: Callable[["Scene"], None] | None = None,
            progress: bool = False, label: str = "run") -> None:
        """Runs ``steps`` steps in C++.

        If ``every`` > 0, the loop returns to Python every ``every`` steps to call
        ``callback(scene)`` (never per contact) and, with ``progress``, to print a line.
        """
        if (isinstance(steps, (bool, str, bytes))
                or not isinstance(steps, (int, float, np.integer, np.floating))
                or not float(steps).is_integer()):
            raise ParameterError(f"steps={steps!r}: must be a whole number of steps")
        steps = int(steps)
        if (isinstance(every, (bool, str, bytes))
                or not isinstance(every, (int, float, np.integer, np.floating))
                or not float(every).is_integer() or every < 0):
            raise ParameterError(f"every={every!r}: must be a whole number of steps >= 0 (0: "
                                 "no callback)")
        every = int(every)
        if steps < 0:
            raise ParameterError(f"steps={steps}: must be >= 0")
        if steps > _MAX_STEPS:
            raise ParameterError(f"steps={steps}: must be <= {_MAX_STEPS} (2**63 - 1) in one "
                                 "call")
        self._check_geometry()
        self._check_controllers()
        self._check_time_step()
        _auto_threads(self.num_bodies)
        if every <= 0:
            self._run(steps)
            self._check_controller_limits()
            return
        t0 = _time.perf_counter()
        done = 0
        while done < steps:
            n = min(every, steps - done)
            self._run(n)
            self._check_controller_limits(end=done + n >= steps)
            done += n
            if callback is not None:
                callback(self)
            if progress:
                el = _time.perf_counter() - t0
                eta = el / done * (steps - done)
                scaled = ""
                if self.density_scaling:
                    st = self.density_scaling_stats()
                    scaled = (f"density scaling: largest factor {st['max_factor']:.3g}, "
                              f"{100 * st['scaled_share']:.0f} % scaled, "
                              f"I={st['inertial_number']:.2g}  ")
                print(f"[{label}] step {done}/{steps}  t={self.time:.4g} s  dt={self.dt:.3g} s  "
                      f"contacts={self.num_active_contacts}  "
                      f"unbalanced={self.unbalanced_force():.3g}  {scaled}wall {el:.1f} s  "
                      f"ETA {eta:.1f} s", file=sys.stdout, flush=True)
