"""Lumpy, slightly soft fruit-like objects (orange, lime) for the ball-rolling scene.

Every trial draws its own fruit from a seed (`sample_fruit`): size, mass, out-of-round
shape, bumps and dents, and the pose it starts in. The shape is a closed triangle mesh
(`write_fruit_mesh`, an icosphere displaced radially) and `add_fruit` puts it on a
MultibodyPlant as a free body with mass and inertia computed from the mesh volume at
uniform density.

Ranges drawn (per-fruit values, roughly what produce scales and calipers give for
supermarket fruit: navel/Valencia orange 68-76 mm across, 140-200 g, density
~0.85 g/cm^3 (an orange floats); Persian lime 50-60 mm across, 55-65 mm long, 60-90 g,
density ~0.95 g/cm^3):

=================  ========================  ===========================
quantity           orange                    lime
=================  ========================  ===========================
radius (eq. vol.)  0.034 - 0.038 m           0.025 - 0.030 m
mass               density 0.82-0.90 g/cm^3, density 0.92-1.00 g/cm^3,
                   clipped to 0.13-0.20 kg   clipped to 0.06-0.09 kg
elongation         1.00 - 1.06 (axis ratio)  1.10 - 1.25 (prolate, +tips)
out-of-round       +-3 % per axis            +-3 % per axis
bumps / dents      8-14, amplitude 1-3 mm    6-10, amplitude 1-2.5 mm
hydro modulus      1e6 - 3e6 Pa              1.5e6 - 4e6 Pa
point stiffness    6e3 - 1.2e4 N/m           8e3 - 1.6e4 N/m
H-C dissipation    3 - 6 s/m                 3 - 6 s/m
=================  ========================  ===========================

`radius` is the radius of the sphere of equal volume: the controller's sphere prior.
The moduli were 2e5-4e5 Pa (orange) and 3e5-6e5 Pa (lime) before; the firmer values
run a fruit trial about 1.3x faster (real-time factor 0.49 -> 0.62, orange seed 100)
and rolled the same. Pressed with 15 N, an orange still rests on a 4 cm^2 patch.

Contact: the collision geometry is the mesh as a `Convex` (its convex hull: all a flat
table or the tip sphere can touch) with compliant-hydroelastic properties (modulus
above), compliant point-contact properties (stiffness, Hunt-Crossley dissipation, used
by TAMSI/lagged) and SAP's relaxation_time. Under "hydroelastic_with_fallback" the
fruit meets a rigid-hydroelastic table (`make_rigid_hydroelastic`) with a hydroelastic
pressure patch: it rests still on a flat spot. Against geometry without hydroelastic
properties (plain `add_table` box, the Panda tip sphere) Drake falls back to compliant
point contact: one point per pair, fine for the tip, but a fruit on a point-contact
table keeps rocking by a few mm (measured) - so give the table rigid-hydroelastic
properties. The fruit starts at rest: the pose reached by a short settling simulation
from a stable hull facet (`settled_pose`, cached), so a small push rolls it back.
"""
from __future__ import annotations

import hashlib
import json
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.geometry import (AddCompliantHydroelasticProperties,
                              AddRigidHydroelasticProperties, Convex, HalfSpace, Mesh,
                              ProximityProperties, RoleAssign, SceneGraph)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import (AddMultibodyPlant, CoulombFriction, MultibodyPlant,
                                     MultibodyPlantConfig)
from pydrake.multibody.tree import RigidBody, RotationalInertia, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from adaptive_c3.models.drake_warnings import silence_half_space_deformable_warning

ORANGE_COLOR = (1.0, 0.45, 0.0, 1.0)
LIME_COLOR = (0.35, 0.75, 0.1, 1.0)
DEFAULT_MESH_DIR = Path(tempfile.gettempdir()) / "adaptive_c3_fruit_meshes"

# kind -> (radius, density kg/m^3, mass clip, elongation, bump count, bump amplitude,
#          hydro modulus Pa, point stiffness N/m)
_RANGES = {
    "orange": dict(radius=(0.034, 0.038), density=(820.0, 900.0), mass=(0.13, 0.20),
                   elongation=(1.0, 1.06), bumps=(8, 14), amp=(0.001, 0.003),
                   modulus=(1e6, 3e6), stiffness=(6e3, 1.2e4)),
    "lime": dict(radius=(0.025, 0.030), density=(920.0, 1000.0), mass=(0.06, 0.09),
                 elongation=(1.10, 1.25), bumps=(6, 10), amp=(0.001, 0.0025),
                 modulus=(1.5e6, 4e6), stiffness=(8e3, 1.6e4)),
}
FRUIT_KINDS = tuple(_RANGES)
_SUBDIVISIONS = 3       # icosphere: 642 vertices, 1280 triangles
REST_WINDOW = 0.25      # rest on a facet within 0.25 bump amplitudes of the lowest
RELAXATION_TIME = 0.02  # s: SAP's dissipation time scale (SAP ignores H-C)


@dataclass(frozen=True)
class FruitSpec:
    """One fruit: everything needed to rebuild its mesh and body (pure data).

    radius: equal-volume sphere radius [m]; mass [kg]; elongation: prolate axis ratio
    (long axis = body z before the rest pose is applied); axis_scales: extra per-axis
    out-of-roundness factors; bumps: unit centres, heights [m] (+ bump, - dent) and
    angular widths [rad]; hydroelastic_modulus [Pa]; point_stiffness [N/m];
    dissipation: Hunt-Crossley [s/m]; rest_direction: body-frame unit vector the
    initial rest pose tries to put down (picks the stable facet); yaw [rad].
    """
    kind: str
    seed: int
    radius: float
    mass: float
    elongation: float
    axis_scales: tuple
    bump_amplitude: float
    bump_count: int
    bump_centers: tuple
    bump_heights: tuple
    bump_widths: tuple
    hydroelastic_modulus: float
    point_stiffness: float
    dissipation: float
    rest_direction: tuple
    yaw: float
    color: tuple

    @property
    def density(self) -> float:
        return self.mass / (4.0 / 3.0 * np.pi * self.radius ** 3)


def nominal_sphere(kind: str) -> tuple[float, float]:
    """(radius m, mass kg) of the sphere the controller assumes for a fruit kind: the
    middle of the kind's ranges (the paper's prior is a sphere of the fruit's size)."""
    if kind not in _RANGES:
        raise ValueError(f"unknown fruit kind {kind!r}; expected one of {FRUIT_KINDS}")
    r = _RANGES[kind]
    return float(np.mean(r["radius"])), float(np.mean(r["mass"]))


def sample_fruit(kind: str, seed: int) -> FruitSpec:
    """Draws one fruit of `kind` ('orange' | 'lime') reproducibly from `seed`."""
    if kind not in _RANGES:
        raise ValueError(f"unknown fruit kind {kind!r}; expected one of {FRUIT_KINDS}")
    r = _RANGES[kind]
    rng = np.random.default_rng([seed, 0xF2017 + FRUIT_KINDS.index(kind)])
    radius = rng.uniform(*r["radius"])
    mass = float(np.clip(rng.uniform(*r["density"]) * 4 / 3 * np.pi * radius ** 3,
                         *r["mass"]))
    n = int(rng.integers(r["bumps"][0], r["bumps"][1] + 1))
    centers = _unit(rng.normal(size=(n, 3)))
    amp = rng.uniform(*r["amp"])
    heights = amp * rng.uniform(0.4, 1.0, n) * rng.choice([-1.0, 1.0], n)
    heights[0] = amp   # at least one full-size bump
    widths = rng.uniform(0.35, 0.6, n)
    return FruitSpec(
        kind=kind, seed=int(seed), radius=float(radius), mass=mass,
        elongation=float(rng.uniform(*r["elongation"])),
        axis_scales=tuple(float(s) for s in rng.uniform(0.97, 1.03, 3)),
        bump_amplitude=float(amp), bump_count=n,
        bump_centers=tuple(tuple(float(v) for v in c) for c in centers),
        bump_heights=tuple(float(h) for h in heights),
        bump_widths=tuple(float(w) for w in widths),
        hydroelastic_modulus=float(rng.uniform(*r["modulus"])),
        point_stiffness=float(rng.uniform(*r["stiffness"])),
        dissipation=float(rng.uniform(3.0, 6.0)),
        rest_direction=tuple(float(v) for v in _unit(rng.normal(size=3))),
        yaw=float(rng.uniform(-np.pi, np.pi)),
        color=ORANGE_COLOR if kind == "orange" else LIME_COLOR)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _icosphere(subdivisions: int):
    t = (1.0 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9),
             (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2),
             (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
             (8, 6, 7), (9, 8, 1)]
    verts = [tuple(_unit(v)) for v in verts]
    for _ in range(subdivisions):
        cache, new_faces = {}, []

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in cache:
                cache[key] = len(verts)
                verts.append(tuple(_unit(np.add(verts[i], verts[j]) / 2)))
            return cache[key]
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    return np.array(verts), np.array(faces, dtype=int)


def mass_properties(vertices, faces):
    """Volume, centroid and inertia (about the centroid, per unit density) of a closed,
    outward-oriented triangle mesh, by signed tetrahedra from the origin."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))       # 6 x signed tet volume
    volume = det.sum() / 6.0
    s = a + b + c
    centroid = (det[:, None] * s).sum(0) / 24.0 / volume
    second = sum(np.einsum("i,ij,ik->jk", det, v, v) for v in (a, b, c))
    second = (second + np.einsum("i,ij,ik->jk", det, s, s)) / 120.0   # int x x^T dV
    second -= volume * np.outer(centroid, centroid)
    inertia = np.trace(second) * np.eye(3) - second
    return float(volume), centroid, inertia


def fruit_mesh(spec: FruitSpec):
    """(vertices, faces) of the fruit in its body frame (origin at the centroid,
    volume = that of a sphere of radius spec.radius)."""
    u, faces = _icosphere(_SUBDIVISIONS)
    e = spec.elongation
    axes = np.array([e ** (-1 / 3), e ** (-1 / 3), e ** (2 / 3)]) * spec.axis_scales
    r = 1.0 / np.sqrt(((u / axes) ** 2).sum(1))           # ellipsoid, unit mean size
    if spec.kind == "lime":                                # the lime's two nubs
        r += 0.06 * (e - 1.0) / 0.25 * np.exp((np.abs(u[:, 2]) - 1) / 0.02)
    v = u * r[:, None] * spec.radius
    for cen, h, w in zip(spec.bump_centers, spec.bump_heights, spec.bump_widths):
        v += u * (h * np.exp((u @ np.asarray(cen) - 1.0) / w ** 2))[:, None]
    volume, centroid, _ = mass_properties(v, faces)
    v = (v - centroid) * (4 / 3 * np.pi * spec.radius ** 3 / volume) ** (1 / 3)
    return v, faces


def write_fruit_mesh(spec: FruitSpec, path) -> Path:
    """Writes the fruit's closed triangle mesh as a Wavefront .obj; returns the path."""
    v, f = fruit_mesh(spec)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"# adaptive-c3 {spec.kind} seed {spec.seed}"]
    lines += [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in v]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    tmp = path.with_suffix(f".{np.random.default_rng().integers(1 << 30)}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)                                      # atomic for parallel trials
    return path


def cached_mesh_path(spec: FruitSpec, mesh_dir=None) -> Path:
    """The spec's mesh in `mesh_dir` (default: a temp cache dir), written if missing."""
    text = repr((sorted(asdict(spec).items()), _SUBDIVISIONS, REST_WINDOW,
                 RELAXATION_TIME, 1))        # bump the last item when the model changes
    key = hashlib.sha1(text.encode()).hexdigest()[:12]
    path = Path(mesh_dir or DEFAULT_MESH_DIR) / f"{spec.kind}_{spec.seed}_{key}.obj"
    return path if path.exists() else write_fruit_mesh(spec, path)


def rest_pose(spec: FruitSpec, xy=(0.0, 0.0), table_top_z: float = 0.0):
    """A statically stable pose resting on a convex-hull facet of the fruit.

    Among the hull facets on which the centroid projects inside the facet (stable flat
    spots) and that lie within REST_WINDOW bump amplitudes of the lowest one (deep
    basins: a fruit does not rest on a ridge; a lime lies on its side), takes the one
    whose outward normal is closest to spec.rest_direction, turns it to face down,
    applies spec.yaw about the vertical and puts the facet on the table top.
    Returns (X_WB, rest height of the centroid above the table).
    """
    from scipy.spatial import ConvexHull
    v, _ = fruit_mesh(spec)
    hull = ConvexHull(v)
    stable = []
    for simplex, eq in zip(hull.simplices, hull.equations):
        n, dist = eq[:3], -eq[3]                          # n.x = dist on the facet
        p = n * dist                                       # centroid's projection
        a, b, c = v[simplex]
        if all(np.dot(np.cross(q1 - q0, p - q0), n) >= 0
               for q0, q1 in ((a, b), (b, c), (c, a))):
            stable.append((n, dist))
    lowest = min(d for _, d in stable)
    deep = [(n, d) for n, d in stable
            if d <= lowest + REST_WINDOW * spec.bump_amplitude]
    n, dist = max(deep, key=lambda nd: nd[0] @ np.asarray(spec.rest_direction))
    R_down = RotationMatrix.MakeFromOneVector(-n, 2).inverse()   # maps n to -z
    R_WB = RotationMatrix.MakeZRotation(spec.yaw) @ R_down
    return RigidTransform(R_WB, [xy[0], xy[1], table_top_z + dist]), float(dist)


def fruit_proximity_properties(spec: FruitSpec, mu: float) -> ProximityProperties:
    """Compliant hydroelastic + compliant point contact properties of the fruit."""
    props = ProximityProperties()
    AddCompliantHydroelasticProperties(resolution_hint=spec.radius / 2,
                                       hydroelastic_modulus=spec.hydroelastic_modulus,
                                       properties=props)
    props.AddProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
    props.AddProperty("material", "point_contact_stiffness",
                     float(spec.point_stiffness))
    props.AddProperty("material", "hunt_crossley_dissipation",
                     float(spec.dissipation))
    props.AddProperty("material", "relaxation_time", float(RELAXATION_TIME))
    return props


def settled_pose(spec: FruitSpec, mesh_dir=None, mu: float = 1.0,
                 max_time: float = 4.0):
    """(R_WB, centroid height) of the fruit come to rest on a flat rigid
    table, starting from rest_pose: a short SAP simulation (time step 1e-3) on a
    rigid-hydroelastic half space with the fruit's own contact properties, until its
    speed and rolling speed are below 0.3 mm/s (or max_time). Cached next to the mesh.
    The compliant contact patch moves the true equilibrium a few mm from the rigid
    hull's facet; starting here the fruit stays put instead of creeping off."""
    path = cached_mesh_path(spec, mesh_dir).with_suffix(f".mu{mu:g}.rest.json")
    if path.exists():
        d = json.loads(path.read_text())
        return RotationMatrix(Quaternion(d["wxyz"])), d["height"]
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=1e-3, discrete_contact_approximation="sap"), builder)
    silence_half_space_deformable_warning()
    ground = ProximityProperties()
    AddRigidHydroelasticProperties(properties=ground)
    ground.AddProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform(), HalfSpace(),
                                    "ground", ground)   # 20x faster queries than a box
    body = add_fruit(plant, spec, position=(0.0, 0.0), mu=mu, mesh_dir=mesh_dir,
                     settle=False, visual=False)
    plant.Finalize()
    sim = Simulator(builder.Build())
    ctx = plant.GetMyContextFromRoot(sim.get_context())
    slow = 0
    while sim.get_context().get_time() < max_time and slow < 5:
        sim.AdvanceTo(sim.get_context().get_time() + 0.02)
        V = plant.EvalBodySpatialVelocityInWorld(ctx, body)
        fast = max(np.linalg.norm(V.translational()),
                   np.linalg.norm(V.rotational()) * spec.radius)
        slow = slow + 1 if fast < 3e-4 else 0
    X = plant.EvalBodyPoseInWorld(ctx, body)
    tmp = path.with_suffix(f".{np.random.default_rng().integers(1 << 30)}.tmp")
    tmp.write_text(json.dumps({"wxyz": X.rotation().ToQuaternion().wxyz().tolist(),
                               "height": float(X.translation()[2]),
                               "time": sim.get_context().get_time()}))
    tmp.replace(path)
    return X.rotation(), float(X.translation()[2])


def add_fruit(plant: MultibodyPlant, spec: FruitSpec, *, name: str = "fruit",
              position=(0.65, 0.0), mu: float = 1.0, mesh_dir=None,
              table_top_z: float = 0.0, settle: bool = True,
              visual: bool = True) -> RigidBody:
    """Adds the fruit as a free body `name` (own model instance `name`).

    Mass spec.mass, inertia of the mesh at uniform density (about the centroid = body
    origin), visual = the bumpy mesh in spec.color, collision = its convex hull with
    fruit_proximity_properties. Default pose: at (x, y) = position[:2] on the table
    top, at rest (settled_pose; settle=False: rest_pose, the rigid hull's facet, which
    may creep a few mm). Call before Finalize().
    """
    path = cached_mesh_path(spec, mesh_dir)
    v, f = fruit_mesh(spec)
    volume, _, unit_inertia = mass_properties(v, f)
    density = spec.mass / volume
    I = RotationalInertia(*(density * unit_inertia[[0, 1, 2, 0, 0, 1],
                                                   [0, 1, 2, 1, 2, 2]]))
    instance = plant.AddModelInstance(name)
    body = plant.AddRigidBody(name, instance, SpatialInertia.MakeFromCentralInertia(
        spec.mass, np.zeros(3), I))
    plant.RegisterCollisionGeometry(body, RigidTransform(), Convex(str(path)),
                                    f"{name}_collision",
                                    fruit_proximity_properties(spec, mu))
    if visual:
        plant.RegisterVisualGeometry(body, RigidTransform(), Mesh(str(path)),
                                     f"{name}_visual", np.asarray(spec.color, float))
    if settle:
        R_WB, height = settled_pose(spec, mesh_dir, mu)
        X_WB = RigidTransform(R_WB, [position[0], position[1], table_top_z + height])
    else:
        X_WB, _ = rest_pose(spec, position[:2], table_top_z)
    plant.SetDefaultFloatingBaseBodyPose(body, X_WB)
    return body


def make_rigid_hydroelastic(plant: MultibodyPlant, scene_graph: SceneGraph,
                            geometry_name: str = "table_collision") -> None:
    """Gives an already registered collision geometry (default: add_table's box)
    rigid-hydroelastic properties, keeping its friction, so the compliant fruit meets
    it with hydroelastic contact instead of single-point fallback contact. Call after
    the geometry is registered and before a context is created."""
    inspector = scene_graph.model_inspector()
    for gid in inspector.GetAllGeometryIds():
        if inspector.GetName(gid).split("::")[-1] == geometry_name and \
                inspector.GetProximityProperties(gid) is not None:
            props = ProximityProperties(inspector.GetProximityProperties(gid))
            if not props.HasProperty("hydroelastic", "compliance_type"):
                AddRigidHydroelasticProperties(properties=props)
            scene_graph.AssignRole(plant.get_source_id(), gid, props,
                                   RoleAssign.kReplace)
            return
    raise ValueError(f"no collision geometry named {geometry_name!r}")
