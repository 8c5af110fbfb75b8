"""Rigid worlds: the model (bodies, materials, parameters), the state, and simulation runs.

Model/state separation: a :class:`World` holds what does not change (shapes, materials,
masses, kinematic paths, step parameters) as frozen data and the stepper's compiled records
(physics.rigid.model: Model, Options); a :class:`WorldState` holds time, poses (position of each centre
of mass in m, unit quaternion of its principal frame) and body-frame twists (rad/s, m/s).
:func:`simulate` runs a world from a state and returns the contact records
(physics.rigid.stepper) plus sampled poses; physics.rigid.events turns records into Impact
events, ContactTracks and haptic frames.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from jassy.errors import JassyError
from physics.rigid import codes
from physics.rigid import stepper as st
from physics.rigid.impulses import new_warm_start
from physics.rigid.integrate import METHODS
from physics.rigid.meshgrid import build_grid
from physics.rigid.model import Geometry, Model, Options, empty_model_tables
from physics.rigid.shapes import (
    BOX,
    CAPSULE,
    COMPOUND,
    CONVEX,
    MESH,
    PLANE,
    SPHERE,
    Box,
    Plane,
    Shape,
    TriangleMesh,
    bounding_radius,
    mass_properties,
)
from physics.rigid.step_units import compile_step_ahead


@dataclass(frozen=True)
class Material:
    """density (kg/m^3), Newton restitution e in [0, 1], Coulomb friction mu >= 0, rolling
    resistance length (m: the rolling torque is bounded by rolling * normal force)."""

    name: str
    density: float
    restitution: float
    friction: float
    rolling: float = 0.0

    def __post_init__(self):
        checks = {
            "density": self.density > 0,
            "restitution": 0 <= self.restitution <= 1,
            "friction": self.friction >= 0,
            "rolling": self.rolling >= 0,
        }
        for key, ok in checks.items():
            if not ok or not np.isfinite(getattr(self, key)):
                raise JassyError(f"Material {self.name!r}.{key}: got {getattr(self, key)!r}, out of range")


MATERIALS = {
    "steel": Material("steel", 7850.0, 0.6, 0.3, 2e-5),
    "wood": Material("wood", 650.0, 0.45, 0.45, 2e-4),
    "glass": Material("glass", 2500.0, 0.7, 0.25, 2e-5),
    "ceramic": Material("ceramic", 2400.0, 0.6, 0.4, 5e-5),
    "rubber": Material("rubber", 1100.0, 0.8, 0.9, 1e-3),
    "plastic": Material("plastic", 1100.0, 0.55, 0.35, 1e-4),
    "food": Material("food", 1000.0, 0.25, 0.5, 5e-4),
}


@dataclass(frozen=True)
class Body:
    """A body of the model. ``kind``: "dynamic", "static" or "kinematic" (follows ``path``, a
    vectorised function of times (T,) s -> (positions (T, 3) m, quaternions (T, 4)), e.g. a
    hand-held wok). How a body sounds is not physics: scenes keep it beside the world
    (patches.rigid_sound.Voice)."""

    name: str
    shape: Shape
    material: Material
    kind: str = "dynamic"
    path: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.kind not in ("dynamic", "static", "kinematic"):
            raise JassyError(
                f"Body {self.name!r}.kind: expected dynamic, static or kinematic, got {self.kind!r}"
            )
        if self.kind == "kinematic" and self.path is None:
            raise JassyError(
                f"Body {self.name!r}.path: a kinematic body needs a path times -> (positions, quaternions)"
            )
        if self.kind == "dynamic" and isinstance(self.shape, (Plane, TriangleMesh)):
            raise JassyError(f"Body {self.name!r}.shape: a {type(self.shape).__name__} cannot be dynamic")


@dataclass(frozen=True)
class StepParams:
    """h (s) outer step; integrator semi-implicit | rk4 | adaptive; contact impulse | linear |
    hunt-crossley; gravity (m/s^2); PGS iterations and relative tolerance; slop (m) below
    which a gap counts as touching; bounce_threshold (m/s) approach speed above which a
    contact is an impact (restitution, an Impact event); beta: penetration recovery per step;
    max_events: impact sub-steps per step; stiffness k (N/m^p), damping c (N s/m or N s/m^(p+1)),
    exponent p and friction regularisation speed (m/s) of the penalty models."""

    h: float = 1e-3
    integrator: str = "semi-implicit"
    contact: str = "impulse"
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    iterations: int = 60
    tolerance: float = 1e-9
    slop: float = 1e-6
    bounce_threshold: float = 0.1
    beta: float = 0.2
    max_events: int = 8
    adaptive_tolerance: float = 1e-9
    stiffness: float = 1e5
    damping: float = 10.0
    exponent: float = 1.5
    friction_speed: float = 1e-3

    def options(self) -> Options:
        """The step settings as the stepper's :class:`model.Options` record (codes for names)."""
        if self.integrator not in METHODS:
            raise JassyError(
                f"StepParams.integrator: expected one of {sorted(METHODS)}, got {self.integrator!r}"
            )
        if self.contact not in codes.CONTACT_MODELS:
            raise JassyError(
                f"StepParams.contact: expected one of {sorted(codes.CONTACT_MODELS)}, got {self.contact!r}"
            )
        if not (self.h > 0 and np.isfinite(self.h)):
            raise JassyError(f"StepParams.h: expected a positive step in s, got {self.h!r}")
        gx, gy, gz = (float(g) for g in self.gravity)
        return Options(
            h=float(self.h),
            gx=gx,
            gy=gy,
            gz=gz,
            slop=float(self.slop),
            bounce_threshold=float(self.bounce_threshold),
            beta=float(self.beta),
            iterations=int(self.iterations),
            tolerance=float(self.tolerance),
            integrator=METHODS[self.integrator],
            adaptive_tolerance=float(self.adaptive_tolerance),
            contact=codes.CONTACT_MODELS[self.contact],
            stiffness=float(self.stiffness),
            damping=float(self.damping),
            exponent=float(self.exponent),
            max_events=int(self.max_events),
            friction_speed=float(self.friction_speed),
        )


@dataclass
class WorldState:
    """time (s); pos (N, 3) centre-of-mass positions (m); quat (N, 4) unit quaternions (w, x,
    y, z) of the principal frames; phi (N, 6) body-frame twists (rad/s, m/s)."""

    time: float
    pos: np.ndarray
    quat: np.ndarray
    phi: np.ndarray

    def copy(self) -> WorldState:
        return WorldState(self.time, self.pos.copy(), self.quat.copy(), self.phi.copy())


@dataclass(frozen=True)
class Placement:
    """Initial pose and velocity of a body, in world coordinates (shape frame origin at
    ``position``, rotated by ``quaternion``; linear velocity of the centre of mass, angular
    velocity)."""

    position: tuple = (0.0, 0.0, 0.0)
    quaternion: tuple = (1.0, 0.0, 0.0, 0.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)


class World:
    """The model: bodies with their shapes and materials, and step parameters."""

    def __init__(self, params: StepParams | None = None):
        self.params = params or StepParams()
        self.bodies: list[Body] = []
        self.placements: list[Placement] = []
        self._geo = None

    def add(self, body: Body, placement: Placement | None = None) -> int:
        """Add a body at its initial placement; returns its index."""
        if any(b.name == body.name for b in self.bodies):
            raise JassyError(f"World.add: a body named {body.name!r} exists already")
        self.bodies.append(body)
        self.placements.append(placement or Placement())
        self._geo = None
        return len(self.bodies) - 1

    def index(self, name: str) -> int:
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i
        raise JassyError(f"World: no body named {name!r} (have {[b.name for b in self.bodies]})")

    # -- compiled model ---------------------------------------------------------------------
    def model(self) -> Model:
        """The stepper's :class:`model.Model` of the bodies (built once, rebuilt after add)."""
        return self._compiled()[0]

    def frames(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """frames[i] = (com, rotation) of body i's principal frame in its shape frame."""
        return self._compiled()[1]

    def _compiled(self):
        if self._geo is None:
            self._geo = _build_model(self.bodies)
        return self._geo

    def initial_state(self) -> WorldState:
        """WorldState of the placements (shape-frame poses moved to the principal frames)."""
        frames = self.frames()
        n = len(self.bodies)
        pos, quat, phi = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 6))
        for i, (body, pl) in enumerate(zip(self.bodies, self.placements, strict=False)):
            if body.kind == "kinematic":
                ps, qs = _path_samples(body, np.zeros(1))
                p, q = ps[0], qs[0]
            else:
                p, q = np.asarray(pl.position, float), np.asarray(pl.quaternion, float)
            pos[i], quat[i] = _principal_pose(p, q, *frames[i])
            rot = _quat_matrix(quat[i])
            phi[i, :3] = rot.T @ np.asarray(pl.angular_velocity, float)
            phi[i, 3:] = rot.T @ np.asarray(pl.velocity, float)
        return WorldState(0.0, pos, quat, phi)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    from physics.rigid.spatial import rotation_matrices

    return rotation_matrices(np.asarray(q, float)[None])[0]


def _matrix_quat(r: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation matrix (Shepperd's method)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(r).as_quat()
    return np.array([w, x, y, z])


def _principal_pose(position, quaternion, com, rotation):
    """World pose of the principal frame given the shape frame's pose."""
    q = np.asarray(quaternion, float)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm < 1e-12:
        raise JassyError(f"Placement.quaternion: expected a non-zero quaternion, got {quaternion!r}")
    r_shape = _quat_matrix(q / norm)
    return np.asarray(position, float) + r_shape @ com, _matrix_quat(r_shape @ rotation)


def _polytope(mesh, com, rotation):
    """Polytope tables of a convex trimesh (shape frame) in the principal frame: (vertices,
    face planes (n, d), hull triangles, edges (E, 18): for each edge of the hull between two
    faces that are not coplanar, its end points p, q, the outward unit normals n1, n2 of those
    two faces (the edge's arc on the Gauss map, for narrow._edge_separation), n2 x n1 (the
    normal of the arc's plane) and q - p)."""
    verts = (np.asarray(mesh.vertices) - com) @ rotation
    tris = verts[np.asarray(mesh.faces)]
    normals = np.asarray(mesh.face_normals) @ rotation
    offsets = np.einsum("ij,ij->i", normals, tris[:, 0])
    planes = np.unique(np.round(np.c_[normals, offsets], 12), axis=0)  # coplanar triangles share a plane
    folded = np.asarray(mesh.face_adjacency_angles) > 1e-9
    ends = np.asarray(mesh.face_adjacency_edges)[folded]
    faces = np.asarray(mesh.face_adjacency)[folded]
    p, q, n1, n2 = verts[ends[:, 0]], verts[ends[:, 1]], normals[faces[:, 0]], normals[faces[:, 1]]
    edges = np.c_[p, q, n1, n2, np.cross(n2, n1), q - p]
    return verts, planes, tris, edges


def _shape_polytopes(shape, com, rotation):
    """Polytope tables (_polytope) of a box or convex body (one) or of a compound's pieces."""
    import trimesh

    if isinstance(shape, Box):
        return [
            _polytope(
                trimesh.creation.box(extents=2.0 * np.asarray(shape.half_extents, float)), com, rotation
            )
        ]
    if shape.kind == CONVEX:
        return [_polytope(shape.hull, com, rotation)]
    return [_polytope(hull, com, rotation) for hull in shape.hulls]


def _build_model(bodies: list[Body]) -> tuple[Model, list]:
    n = len(bodies)
    btype = np.zeros(n, np.int64)
    kind = np.zeros(n, np.int64)
    param = np.zeros((n, 4))
    bound = np.zeros(n)
    mass = np.ones(n)
    inertia = np.ones((n, 3))
    inv_mass = np.zeros(n)
    inv_inertia = np.zeros((n, 3))
    rest, fric, roll = (
        np.array([getattr(b.material, k) for b in bodies], float)
        for k in ("restitution", "friction", "rolling")
    )
    frames = []
    slots = [None] * n  # geometry slot i: body i's polytope; compound pieces after the bodies
    pieces = []  # per body, its geometry slots (a box or convex body: its own)
    mesh_id = np.full(n, -1, np.int64)
    grids = []
    kinds = {"dynamic": codes.DYNAMIC, "static": codes.STATIC, "kinematic": codes.KINEMATIC}
    for i, body in enumerate(bodies):
        shape = body.shape
        btype[i] = shape.kind
        kind[i] = kinds[body.kind]
        if body.kind == "dynamic":
            props = mass_properties(shape, body.material.density)
            com, rotation = props.com, props.rotation
            mass[i], inertia[i] = props.mass, props.inertia
            inv_mass[i], inv_inertia[i] = 1.0 / props.mass, 1.0 / props.inertia
        else:
            com, rotation = np.zeros(3), np.eye(3)
        frames.append((com, rotation))
        bound[i] = bounding_radius(shape, com, rotation)
        pieces.append([])
        if shape.kind == SPHERE:
            param[i, 0] = shape.radius
        elif shape.kind == CAPSULE:
            param[i, :2] = shape.radius, shape.half_length
        elif shape.kind in (BOX, CONVEX):
            slots[i] = _shape_polytopes(shape, com, rotation)[0]
            pieces[i] = [i]
        elif shape.kind == COMPOUND:
            for table in _shape_polytopes(shape, com, rotation):
                pieces[i].append(len(slots))
                slots.append(table)
        elif shape.kind == PLANE:
            nrm = np.asarray(shape.normal, float)
            param[i, :3] = nrm / np.linalg.norm(nrm)
            param[i, 3] = shape.offset / np.linalg.norm(nrm)
        elif shape.kind == MESH:
            param[i, :2] = shape.thickness, shape.depth
            mesh_id[i] = len(grids)
            grids.append(
                build_grid(np.asarray(shape.surface.vertices, float), np.asarray(shape.surface.faces))
            )
    tables = [_slot_table(slots, k) for k in range(4)]
    point_start, points = _point_table(bodies, frames, slots)
    piece_start, piece_slots = _slot_table([np.asarray(p, np.int64) for p in pieces], None)
    geometry = Geometry(
        shape_type=btype,
        param=param,
        bound=bound,
        vert_start=tables[0][0],
        verts=tables[0][1],
        plane_start=tables[1][0],
        planes=tables[1][1],
        hull_start=tables[2][0],
        hull_tris=tables[2][1],
        mesh_of=mesh_id,
        **_mesh_tables(grids),
        point_start=point_start,
        points=points,
        edge_start=tables[3][0],
        edges=tables[3][1],
        piece_start=piece_start,
        piece_slots=piece_slots,
    )
    model = Model(
        geometry=geometry,
        kind=kind,
        mass=mass,
        inertia=inertia,
        inv_mass=inv_mass,
        inv_inertia=inv_inertia,
        restitution=rest,
        friction=fric,
        rolling=roll,
        kinematic=np.flatnonzero(kind == codes.KINEMATIC).astype(np.int64),
    )
    return model, frames


def _slot_table(slots, k):
    """(starts (S + 1,), rows concatenated) of table k of each geometry slot's polytope
    (_polytope; k = None: slots holds the tables themselves); an empty slot has no rows."""
    shapes = ((0, 3), (0, 4), (0, 3, 3), (0, 18))
    rows = []
    for slot in slots:
        if k is None:
            rows.append(slot)
            continue
        table = (
            np.zeros(shapes[k]) if slot is None else np.asarray(slot[k], float).reshape((-1, *shapes[k][1:]))
        )
        rows.append(table)
    starts = np.cumsum([0] + [len(r) for r in rows]).astype(np.int64)
    empty = np.zeros(0, np.int64) if k is None else np.zeros(shapes[k])
    return starts, np.concatenate(rows) if rows else empty


def _point_table(bodies, frames, slots) -> tuple[np.ndarray, np.ndarray]:
    """The points standing for each body against planes and meshes (narrow.body_point): (offsets
    (N + 1,): body i's rows are offsets[i] to offsets[i + 1]; rows (P, 4): body-frame position
    and radius, m): a sphere's centre, a capsule's axis ends and middle, a polytope's vertices,
    a compound's surface vertices."""
    rows = []
    for i, body in enumerate(bodies):
        shape = body.shape
        if shape.kind == SPHERE:
            rows.append([[0.0, 0.0, 0.0, shape.radius]])
        elif shape.kind == CAPSULE:
            rows.append([[0.0, 0.0, (j - 1) * shape.half_length, shape.radius] for j in range(3)])
        elif shape.kind in (BOX, CONVEX):
            rows.append(np.c_[slots[i][0], np.zeros(len(slots[i][0]))])
        elif shape.kind == COMPOUND:
            com, rotation = frames[i]
            v = (np.asarray(shape.surface.vertices, float) - com) @ rotation
            rows.append(np.c_[v, np.zeros(len(v))])
        else:
            rows.append(np.zeros((0, 4)))
    offsets = np.cumsum([0] + [len(r) for r in rows]).astype(np.int64)
    return offsets, np.concatenate([np.asarray(r, float).reshape(-1, 4) for r in rows])


def _mesh_tables(grids) -> dict[str, np.ndarray]:
    """The mesh fields of :class:`model.Geometry`: the triangle grids concatenated."""
    if not grids:
        return empty_model_tables()
    return {
        "tri_start": np.cumsum([0] + [len(g.triangles) for g in grids]).astype(np.int64),
        "tris": np.concatenate([g.triangles for g in grids]),
        "tri_normals": np.concatenate([g.normals for g in grids]),
        "grid_origin_cell": np.array([[*g.origin, g.cell] for g in grids]),
        "grid_dims": np.array([g.dims for g in grids], np.int64),
        "cell_start": np.cumsum([0] + [len(g.start) for g in grids]).astype(np.int64),
        "cell_items_start": np.concatenate([g.start for g in grids]),
        "item_start": np.cumsum([0] + [len(g.items) for g in grids]).astype(np.int64),
        "cell_items": np.concatenate([g.items for g in grids]),
        "tri_spheres": np.concatenate([g.spheres for g in grids]),
    }


@dataclass
class RunResult:
    """Contact records (rows, codes.REC_* columns), sampled poses every ``sample_every``
    steps (times (S,), pos (S, N, 3), quat (S, N, 4), phi (S, N, 6)), the start time (s), the
    final state, and stepper statistics (impact sub-steps, late impacts, contacts, solves)."""

    world: World
    start_time: float
    records: np.ndarray
    times: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    phi: np.ndarray
    state: WorldState
    stats: dict


def simulate(
    world: World,
    duration: float,
    state: WorldState | None = None,
    sample_every: int = 1,
    chunk: int = 2000,
    keep_records: bool = True,
    compile_units: Sequence[Callable[[], object]] = (),
) -> RunResult:
    """Run ``world`` for ``duration`` seconds (a whole number of steps of world.params.h),
    sampling the poses after every ``sample_every`` steps (0: only the final state).
    ``keep_records=False`` keeps no contact records (RunResult.records is empty; the counts in
    stats stay): the stepper writes them into one buffer reused from its start, instead of a
    run-long buffer whose every page is new memory (a settled pile of 1000 bodies writes
    ~0.6 MB of records per step). ``compile_units``: the caller's compile units (e.g. a
    scene's sound kernels) for the helper that compiles the step on a cold kernel cache
    (:func:`physics.rigid.step_units.compile_step_ahead`); ignored on a filled cache."""
    opt = world.params.options()
    h = opt.h
    if not (duration > 0 and np.isfinite(duration)):
        raise JassyError(f"simulate: duration: expected a positive time in s, got {duration!r}")
    if sample_every < 0:
        raise JassyError(f"simulate: sample_every: expected an integer >= 0, got {sample_every!r}")
    model = world.model()
    state = (state or world.initial_state()).copy()
    n = len(world.bodies)
    n_steps = int(round(duration / h))
    first = int(round(state.time / h))
    every = sample_every or n_steps + 1
    traj = np.zeros((n_steps // every, n, 13))
    # records: a few per body and step reserved up front (address space only: the memory of a
    # row comes when the stepper writes it), so that the buffer seldom grows by copying
    rows = min(max(4096, 4 * n * n_steps), 1 << 20) if keep_records else max(1 << 16, 200 * n)
    rec = np.empty((rows, codes.REC_WIDTH))
    nrec = 0
    stats = st.new_stats()
    warm = new_warm_start(st.MAX_CONTACTS)
    done = 0
    last = None  # the last chunk's Data
    while done < n_steps:
        todo = min(chunk, n_steps - done)
        kin_pos, kin_quat = _kinematic_samples(world, model.kinematic, first + done, todo, h)
        data = st.new_data(
            model,
            opt,
            state.pos,
            state.quat,
            state.phi,
            kin_pos,
            kin_quat,
            rec,
            stats,
            traj,
            every,
            first,
            warm,
        )
        if last is not None:
            data = st.carry_scratch(data, last)  # the scratch grown so far, not grown again
        else:
            compile_step_ahead(model, opt, data, compile_units)  # on an empty kernel cache: on two cores
        last, steps, nrec = st.run(model, opt, data, first + done, todo, nrec)
        rec = last.rec  # grown when a step resumed with too little room
        if steps < todo and not keep_records and nrec > 0:
            nrec = 0  # the records are not kept: write over them
        elif steps < todo:  # the record buffer might not hold the next step: grow it
            rec = st.grown_records(rec, nrec, 0)
        done += steps
        if not (np.all(np.isfinite(state.pos)) and np.all(np.isfinite(state.phi))):
            raise JassyError(f"simulate: the state became non-finite near t = {(first + done) * h:.6f} s")
    state.time = (first + n_steps) * h
    info = {name: int(count[0]) for name, count in zip(stats._fields, stats, strict=True)}
    times = (first + every * np.arange(1, traj.shape[0] + 1)) * h
    return RunResult(
        world,
        first * h,
        rec[: nrec if keep_records else 0],  # no copy: rows beyond were never written, so never given memory
        times,
        traj[:, :, :3].copy(),
        traj[:, :, 3:7].copy(),
        traj[:, :, 7:].copy(),
        state,
        info,
    )


def _path_samples(body: Body, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(positions (T, 3), unit quaternions (T, 4)) of a kinematic body's path at ``times``."""
    pos, quat = body.path(times)
    pos, quat = np.asarray(pos, float), np.asarray(quat, float)
    if pos.shape != (times.size, 3) or quat.shape != (times.size, 4):
        raise JassyError(
            f"Body {body.name!r}.path: expected arrays ({times.size}, 3) and ({times.size}, 4) for "
            f"{times.size} times, got {pos.shape} and {quat.shape}"
        )
    norms = np.linalg.norm(quat, axis=1, keepdims=True)
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(norms)) and np.all(norms > 1e-12)):
        raise JassyError(f"Body {body.name!r}.path: expected finite positions and non-zero quaternions")
    return pos, quat / norms


def _kinematic_samples(world, kin_index, first, steps, h):
    """Poses of the kinematic bodies at steps first .. first + steps."""
    times = (first + np.arange(steps + 1)) * h
    pos = np.zeros((steps + 1, len(kin_index), 3))
    quat = np.zeros((steps + 1, len(kin_index), 4))
    for j, i in enumerate(kin_index):
        pos[:, j], quat[:, j] = _path_samples(world.bodies[i], times)
    return pos, quat  # a kinematic body's frame is its shape frame
