"""Bounding ellipsoids and boxes of each body's geometry (idkit.robots.geometry, .bounding, .meshes).

References independent of the code under test: closed forms (a box's minimum-volume ellipsoid is √3
times its half-extents, a cylinder's √(3/2) r and √3 h), an interior-point solver (cvxpy + Clarabel)
for the minimum volume, pinocchio for where a URDF puts a welded link's geometry, and the readers'
own inertials (a centre of mass placed at a geom's position must coincide with it in the body frame).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from idkit.robots.bounding import Solid, ellipsoid_bound, minimum_volume_ellipsoid
from idkit.robots.geometry import _bound, body_geometry
from idkit.robots.inertia import centroidal, pseudo_inertia_rows, standard_parameters
from idkit.robots.mjcf import MJCFRobot
from idkit.robots.urdf import URDFRobot

# ruff: noqa: E501  (the test URDF and MJCF below keep one element per line)

INERTIAL = '<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'


@functools.cache
def robot_for(urdf: str) -> URDFRobot:
    return URDFRobot(urdf)


def one_link_urdf(link_body: str, joint_origin: str = 'xyz="0 0 0.5"') -> str:
    """A URDF with one revolute joint whose child link ``a`` holds ``link_body``."""
    return f"""<robot name="one">
  <link name="world"/>
  <link name="a">{INERTIAL}{link_body}</link>
  <joint name="j" type="revolute"><parent link="world"/><child link="a"/><origin {joint_origin}/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def surface(kind: str, size: np.ndarray, rng: np.random.Generator, n: int = 4000) -> np.ndarray:
    """``[n, 3]`` random points on the true surface of a solid in its own frame (not its sampled hull)."""
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    if kind == "box":
        points = rng.uniform(-1, 1, (n, 3))
        points[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
        return points * size
    if kind == "sphere":
        return direction * size[0]
    if kind == "ellipsoid":
        return direction * size
    if kind == "capsule":
        return direction * size[0] + np.sign(direction[:, 2:]) * [0, 0, size[1]]
    angle, height = rng.uniform(0, 2 * np.pi, n), rng.uniform(-1, 1, n) * size[1]
    radius = size[0] * np.where(rng.random(n) < 0.5, 1.0, np.sqrt(rng.random(n)))  # side or caps
    height = np.where(radius < size[0], np.sign(height) * size[1], height)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle), height])


def ellipsoid_values(centre: np.ndarray, shape: np.ndarray, points: np.ndarray) -> np.ndarray:
    offsets = points - centre
    return np.einsum("ij,jk,ik->i", offsets, shape, offsets)


SIZES = {
    "box": st.tuples(*[st.floats(0.01, 0.5)] * 3),
    "sphere": st.tuples(st.floats(0.01, 0.5)),
    "ellipsoid": st.tuples(*[st.floats(0.01, 0.5)] * 3),
    "cylinder": st.tuples(st.floats(0.01, 0.5), st.floats(0.0, 0.5)),
    "capsule": st.tuples(st.floats(0.01, 0.5), st.floats(0.0, 0.5)),
}
solids = st.sampled_from(sorted(SIZES)).flatmap(
    lambda kind: st.builds(
        lambda size, rotation, offset: Solid(
            kind, np.array(size), Rotation.from_rotvec(rotation).as_matrix(), np.array(offset)
        ),
        SIZES[kind],
        st.tuples(*[st.floats(-3, 3)] * 3),
        st.tuples(*[st.floats(-0.5, 0.5)] * 3),
    )
)


# --------------------------------------------------------------------------------- primitives
def test_a_box_alone_gets_its_exact_minimum_ellipsoid_root_3_times_its_half_extents():
    robot = URDFRobot(
        one_link_urdf(
            '<collision><origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.5 1.1"/><geometry><box size="0.2 0.4 0.6"/></geometry></collision>'
        )
    )
    geometry = body_geometry(robot).bodies["a"]
    rotation = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()  # URDF rpy: fixed axes x, y, z
    expected = rotation @ np.diag(1 / (3 * np.array([0.1, 0.2, 0.3]) ** 2)) @ rotation.T
    np.testing.assert_allclose(geometry.ellipsoid_centre, [0.1, -0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(geometry.ellipsoid_shape, expected, rtol=1e-10, atol=1e-9)
    corners = Solid("box", np.array([0.1, 0.2, 0.3]), rotation, np.array([0.1, -0.2, 0.3])).points()
    np.testing.assert_allclose(
        ellipsoid_values(geometry.ellipsoid_centre, geometry.ellipsoid_shape, corners), 1.0
    )
    # the general algorithm, given the corners, finds the same ellipsoid
    centre, shape = minimum_volume_ellipsoid(corners)
    np.testing.assert_allclose(centre, [0.1, -0.2, 0.3], atol=1e-6)
    np.testing.assert_allclose(np.linalg.det(shape), np.linalg.det(expected), rtol=1e-5)
    assert geometry.sources == ("a collision box",) and geometry.missing == ()


def test_a_sphere_alone_is_its_own_ellipsoid_and_box():
    robot = URDFRobot(
        one_link_urdf('<visual><origin xyz="0 0.1 0"/><geometry><sphere radius="0.25"/></geometry></visual>')
    )
    geometry = body_geometry(robot).bodies["a"]
    np.testing.assert_allclose(geometry.ellipsoid_centre, [0, 0.1, 0], atol=1e-15)
    np.testing.assert_allclose(geometry.ellipsoid_shape, np.eye(3) / 0.25**2)
    np.testing.assert_allclose(
        [geometry.box_lo, geometry.box_hi], [[-0.25, -0.15, -0.25], [0.25, 0.35, 0.25]]
    )


def test_the_cylinders_closed_form_is_the_minimum_over_its_rims():
    """The closed form (√(3/2) r, √3 h) against the general algorithm on 2,000 exact rim points."""
    angle = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    rim = np.column_stack([0.2 * np.cos(angle), 0.2 * np.sin(angle), np.full(1000, 0.3)])
    centre, shape = minimum_volume_ellipsoid(np.concatenate([rim, rim * [1, 1, -1]]))
    exact = Solid("cylinder", np.array([0.2, 0.3]), np.eye(3), np.zeros(3)).exact_ellipsoid()
    np.testing.assert_allclose(centre, 0, atol=1e-6)
    np.testing.assert_allclose(
        np.sort(1 / np.sqrt(np.linalg.eigvalsh(shape))),
        [np.sqrt(1.5) * 0.2] * 2 + [np.sqrt(3) * 0.3],
        rtol=1e-4,
    )
    np.testing.assert_allclose(shape, exact[1], rtol=1e-4, atol=1e-4)


@settings(max_examples=60, deadline=None)
@given(solids, st.lists(solids, max_size=2), st.integers(0, 2**32 - 1))
def test_the_ellipsoid_and_box_contain_every_solid_whole(first, others, seed):
    """Every point of each solid's true surface (not its sampled hull) is inside the body's ellipsoid
    and box, and the box is tight: the surface reaches each of its faces."""
    rng = np.random.default_rng(seed)
    found = [(f"s{i}", s) for i, s in enumerate([first, *others])]
    geometry = _bound(found, ())
    points = np.concatenate([surface(s.kind, s.size, rng) @ s.rotation.T + s.translation for _, s in found])
    assert ellipsoid_values(geometry.ellipsoid_centre, geometry.ellipsoid_shape, points).max() <= 1 + 1e-9
    assert (points >= geometry.box_lo - 1e-12).all() and (points <= geometry.box_hi + 1e-12).all()
    extent = geometry.box_hi - geometry.box_lo
    np.testing.assert_array_less(geometry.box_hi - points.max(axis=0), 0.05 * extent + 1e-9)
    np.testing.assert_array_less(points.min(axis=0) - geometry.box_lo, 0.05 * extent + 1e-9)


def reference_volume(points: np.ndarray) -> tuple[float, np.ndarray]:
    """The minimum ellipsoid's ``1 / det A`` (∝ volume) and centre by cvxpy's interior-point solver."""
    cp = pytest.importorskip("cvxpy")
    mean, scale = points.mean(axis=0), np.abs(points - points.mean(axis=0)).max()
    unit = (points - mean) / scale
    a, b = cp.Variable((3, 3), PSD=True), cp.Variable(3)
    cp.Problem(
        cp.Maximize(cp.log_det(a)), [cp.norm(unit @ a + np.ones((len(unit), 1)) @ b[None, :], axis=1) <= 1]
    ).solve(solver="CLARABEL")
    return scale**3 / np.linalg.det(a.value), mean - scale * np.linalg.solve(a.value, b.value)


@pytest.mark.parametrize("seed", range(4))
def test_the_minimum_volume_equals_an_interior_point_solvers(seed):
    """Random clouds (stretched, rotated, far from the origin, in mm or km): the same volume to 1e-5 and
    every point inside."""
    rng = np.random.default_rng(seed)
    points = (
        rng.normal(size=(int(rng.integers(5, 400)), 3)) @ rng.normal(size=(3, 3)) + rng.normal(size=3) * 5
    )
    points *= [1e-3, 1.0, 1e3, 1.0][seed]
    centre, shape = minimum_volume_ellipsoid(points)
    volume, reference_centre = reference_volume(points)
    assert np.linalg.det(shape) ** -0.5 == pytest.approx(volume, rel=1e-5)
    np.testing.assert_allclose(centre, reference_centre, atol=1e-4 * np.ptp(points))
    assert ellipsoid_values(centre, shape, points).max() == pytest.approx(1.0, abs=1e-9)


def test_flat_geometry_is_thickened_and_said_a_point_has_none():
    plate = '<collision><geometry><box size="0.4 0.2 0"/></geometry></collision>'
    geometry = body_geometry(URDFRobot(one_link_urdf(plate))).bodies["a"]
    assert geometry.sources[-1] == "flat geometry thickened to ±2 mm"  # 1 % of the largest half-width
    assert np.isfinite(geometry.ellipsoid_shape).all()
    corners = Solid("box", np.array([0.2, 0.1, 0.0]), np.eye(3), np.zeros(3)).points()
    assert ellipsoid_values(geometry.ellipsoid_centre, geometry.ellipsoid_shape, corners).max() <= 1 + 1e-9
    point = body_geometry(
        URDFRobot(one_link_urdf('<collision><geometry><sphere radius="0"/></geometry></collision>'))
    )
    assert point.bodies["a"] is None
    assert point.missing == ("a: a collision sphere (the geometry is a single point)",)


def test_malformed_geometry_is_left_out_and_said():
    elements = (
        '<collision><geometry><box size="0.1 0.2"/></geometry></collision>'
        '<collision><geometry><sphere radius="-1"/></geometry></collision>'
        '<collision><geometry><cone radius="1"/></geometry></collision>'
        '<collision><origin xyz="0 0 x"/><geometry><sphere radius="1"/></geometry></collision>'
    )
    geometry = body_geometry(URDFRobot(one_link_urdf(elements)))
    assert geometry.bodies["a"] is None
    assert geometry.missing == (
        "a: collision box (size='0.1 0.2' is not 3 finite numbers)",
        "a: collision sphere (a negative size)",
        "a: collision cone (<cone> is not a URDF shape (box, cylinder, sphere, mesh))",
        "a: collision sphere (xyz='0 0 x' is not numeric)",
    )
    assert geometry.summary().startswith(
        "geometry bounds 0 of 1 bodies; no usable geometry on a; left out: a: collision box"
    )
    assert geometry.bounded_by() == {"a": "nothing: no usable geometry"}


# ----------------------------------------------------------------------- Wensing, Kim & Slotine
def box_inertial(mass: float, half: np.ndarray, rotation: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Standard parameters of a uniform solid box (closed form ``m/3 (b² + c²)`` about its centre)."""
    principal = (
        mass
        / 3
        * np.array([half[1] ** 2 + half[2] ** 2, half[0] ** 2 + half[2] ** 2, half[0] ** 2 + half[1] ** 2])
    )
    return standard_parameters(mass, centre, rotation @ np.diag(principal) @ rotation.T)


def test_a_uniform_box_keeps_two_thirds_of_its_mass_inside_its_ellipsoid_bound():
    """For the box's own minimum ellipsoid ``tr(J Q4) = m (1 − Σ (a²/3) / (3 a²)) = 2m/3`` (idkit's
    pseudo-inertia layout against the bound's), a shell on the ellipsoid gives 0, a point outside < 0."""
    rotation, centre, half = (
        Rotation.from_rotvec([0.4, -1.0, 0.7]).as_matrix(),
        np.array([0.3, -0.1, 0.5]),
        np.array([0.1, 0.25, 0.05]),
    )
    link = f'<collision><origin xyz="{" ".join(map(str, centre))}" rpy="{" ".join(map(str, Rotation.from_matrix(rotation).as_euler("xyz")))}"/><geometry><box size="{" ".join(map(str, 2 * half))}"/></geometry></collision>'
    geometry = body_geometry(URDFRobot(one_link_urdf(link))).bodies["a"]
    bound = geometry.q4()
    pseudo = np.array(pseudo_inertia_rows(list(box_inertial(2.5, half, rotation, centre))))
    assert np.trace(pseudo @ bound) == pytest.approx(2 / 3 * 2.5, rel=1e-9)
    semi = rotation @ np.diag(np.sqrt(3) * half)  # the ellipsoid's axes: a uniform shell on it
    shell = np.block(
        [[semi @ semi.T / 3 + np.outer(centre, centre), centre[:, None]], [centre[None, :], np.ones((1, 1))]]
    )
    assert np.trace(shell @ bound) == pytest.approx(0.0, abs=1e-9)
    outside = np.append(centre + semi[:, 0] * 1.01, 1.0)
    assert np.trace(np.outer(outside, outside) @ bound) < 0


CYLINDER = one_link_urdf(
    '<collision><origin xyz="0.1 0 0" rpy="0.2 0.3 0.4"/><geometry><cylinder radius="0.3" length="0.8"/></geometry></collision>'
)


@settings(max_examples=200, deadline=None)
@given(st.tuples(*[st.floats(-1, 1)] * 3), st.floats(0.01, 10.0))
def test_a_point_mass_meets_the_bound_iff_it_is_inside(point, mass):
    geometry = body_geometry(robot_for(CYLINDER)).bodies["a"]
    lifted = np.append(point, 1.0)
    margin = np.trace(mass * np.outer(lifted, lifted) @ geometry.q4())
    assert margin == pytest.approx(
        mass
        * (1 - ellipsoid_values(geometry.ellipsoid_centre, geometry.ellipsoid_shape, np.array([point]))[0])
    )
    assert (margin >= 0) == geometry.in_ellipsoid(point) or abs(margin) < 1e-12
    assert ellipsoid_bound(geometry.ellipsoid_centre, geometry.ellipsoid_shape).shape == (4, 4)


# ------------------------------------------------------------------------------------- frames
WELDED = """<robot name="welded">
  <link name="world"/>
  <link name="a"/>
  <link name="flange"/>
  <link name="tool">
    <inertial><origin xyz="0.02 -0.03 0.04" rpy="0.1 0.2 0.3"/><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
    <collision><origin xyz="0.02 -0.03 0.04" rpy="0.1 0.2 0.3"/><geometry><box size="0.04 0.06 0.1"/></geometry></collision>
  </link>
  <joint name="j" type="revolute"><parent link="world"/><child link="a"/><origin xyz="0 0 1" rpy="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="to_flange" type="fixed"><parent link="a"/><child link="flange"/><origin xyz="0.1 0.2 0.3" rpy="0.5 -0.4 1.2"/></joint>
  <joint name="to_tool" type="fixed"><parent link="flange"/><child link="tool"/><origin xyz="0 0 0.15" rpy="0 0.6 0"/></joint>
</robot>"""


def test_a_box_on_a_welded_tool_lands_where_pinocchio_puts_it():
    pin = pytest.importorskip("pinocchio")
    pytest.importorskip("coal")
    urdf = WELDED
    geometry = body_geometry(URDFRobot(urdf)).bodies["a"]
    model = pin.buildModelFromXML(urdf)
    (box,) = pin.buildGeomFromUrdfString(model, urdf, pin.GeometryType.COLLISION).geometryObjects
    assert model.names[box.parentJoint] == "j"
    rotation, translation = box.placement.rotation, box.placement.translation  # in the joint (= body) frame
    np.testing.assert_allclose(geometry.ellipsoid_centre, translation, atol=1e-12)
    expected = rotation @ np.diag(1 / (3 * np.array([0.02, 0.03, 0.05]) ** 2)) @ rotation.T
    np.testing.assert_allclose(geometry.ellipsoid_shape, expected, rtol=1e-9, atol=1e-6)
    assert geometry.sources == ("tool collision box",)


def test_a_geometry_and_an_inertial_at_one_origin_coincide_in_the_body_frame():
    """The reader merges the welded tool's inertial into the body: its centre of mass, placed at the
    box's origin, is the ellipsoid's centre (the frames of the two agree)."""
    robot = URDFRobot(WELDED)
    _, com, _ = centroidal(robot.tree.bodies[0].inertial)
    np.testing.assert_allclose(body_geometry(robot).bodies["a"].ellipsoid_centre, com, atol=1e-12)


# ------------------------------------------------------------------------------------- meshes
CUBE = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (0.0, 2.0)])
TRIANGLES = [
    (0, 1, 3),
    (0, 3, 2),
    (4, 6, 7),
    (4, 7, 5),
    (0, 4, 5),
    (0, 5, 1),
    (2, 3, 7),
    (2, 7, 6),
    (0, 2, 6),
    (0, 6, 4),
    (1, 5, 7),
    (1, 7, 3),
]


def write_meshes(folder) -> None:
    """The cube ``[-1, 1]² × [0, 2]`` as binary STL, ASCII STL and OBJ."""
    folder.mkdir(parents=True, exist_ok=True)
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    triangles = np.zeros(len(TRIANGLES), dtype=record)
    triangles["corners"] = CUBE[np.array(TRIANGLES)]
    (folder / "cube.stl").write_bytes(
        b"solid but binary".ljust(80) + len(TRIANGLES).to_bytes(4, "little") + triangles.tobytes()
    )
    facets = "".join(
        "facet normal 0 0 0\n outer loop\n"
        + "".join(f"  vertex {x:e} {y:e} {z:e}\n" for x, y, z in CUBE[list(t)])
        + " endloop\nendfacet\n"
        for t in TRIANGLES
    )
    (folder / "cube_ascii.STL").write_text(f"solid cube\n{facets}endsolid cube\n")
    vertices = "".join(f"v {x} {y} {z} 0.5 0.5 0.5\n" for x, y, z in CUBE)
    (folder / "cube.obj").write_text(
        "# cube\nvn 0 0 1\nvt 0 0\n"
        + vertices
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in TRIANGLES)
    )


@pytest.mark.parametrize(
    "filename",
    [
        "meshes/cube.stl",
        "meshes/cube_ascii.STL",
        "meshes/cube.obj",
        "package://cubes/meshes/cube.stl",
        "file://{root}/robot/meshes/cube.obj",
    ],
)
def test_stl_and_obj_meshes_are_read_scaled_and_placed(tmp_path, filename):
    write_meshes(tmp_path / "robot" / "meshes")
    mesh = f'<mesh filename="{filename.format(root=tmp_path)}" scale="0.1 0.05 0.2"/>'
    link = f'<collision><origin xyz="0.3 0 0" rpy="0 0 1.5707963267948966"/><geometry>{mesh}</geometry></collision>'
    urdf = tmp_path / "robot" / "robot.urdf"
    urdf.write_text(one_link_urdf(link))
    geometry = body_geometry(URDFRobot(str(urdf)), package_dirs=[tmp_path / "robot"]).bodies["a"]
    # scaled: [-0.1, 0.1] × [-0.05, 0.05] × [0, 0.4]; turned a quarter about z: x ← −y, y ← x; moved 0.3 along x
    np.testing.assert_allclose(
        [geometry.box_lo, geometry.box_hi], [[0.25, -0.1, 0.0], [0.35, 0.1, 0.4]], atol=1e-7
    )
    np.testing.assert_allclose(geometry.ellipsoid_centre, [0.3, 0.0, 0.2], atol=1e-6)
    np.testing.assert_allclose(
        np.sort(1 / np.sqrt(np.linalg.eigvalsh(geometry.ellipsoid_shape))),
        np.sqrt(3) * np.array([0.05, 0.1, 0.2]),
        rtol=1e-5,
    )


def test_a_missing_or_unread_mesh_is_said_and_visual_geometry_stands_in(tmp_path):
    (tmp_path / "part.dae").write_text("<COLLADA/>")
    (tmp_path / "broken.stl").write_bytes(b"\x00" * 100)
    links = {
        "a": '<collision><geometry><mesh filename="package://nowhere/part.stl"/></geometry></collision>'
        '<visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual>',
        "b": '<collision><geometry><mesh filename="part.dae"/></geometry></collision>'
        '<collision><geometry><mesh filename="broken.stl"/></geometry></collision>'
        '<collision><geometry><sphere radius="0.1"/></geometry></collision>'
        '<visual><geometry><box size="9 9 9"/></geometry></visual>',
        "c": '<visual><geometry><mesh filename="gone.obj"/></geometry></visual>',
    }
    joints = "".join(
        f'<joint name="j{link}" type="revolute"><parent link="{parent}"/><child link="{link}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        for parent, link in (("world", "a"), ("a", "b"), ("b", "c"))
    )
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(
        f'<robot name="r"><link name="world"/>{"".join(f"<link name={k!r}>{INERTIAL}{v}</link>" for k, v in links.items())}{joints}</robot>'
    )
    geometry = body_geometry(URDFRobot(str(urdf)))
    assert geometry.bodies["a"].sources == ("a visual box",)
    assert geometry.bodies["b"].sources == ("b collision sphere",)  # the usable collision, not the visual
    assert geometry.bodies["c"] is None
    assert geometry.missing == (
        "a: collision mesh package://nowhere/part.stl (not found: give robot.package_dirs)",
        "b: collision mesh part.dae (.dae is not read (STL and OBJ are))",
        "b: collision mesh broken.stl (is neither binary STL (its size disagrees with its triangle count) nor ASCII STL)",
        "c: visual mesh gone.obj (not found)",
    )
    assert geometry.bodies["b"].missing == geometry.missing[1:3]
    assert "no usable geometry on c" in geometry.summary()


def test_built_once_per_robot_and_read_only(tmp_path):
    robot = URDFRobot(one_link_urdf('<collision><geometry><sphere radius="0.1"/></geometry></collision>'))
    first = body_geometry(robot)
    assert body_geometry(robot) is first and body_geometry(robot, [tmp_path]) is not first
    with pytest.raises(ValueError, match="read-only"):
        first.bodies["a"].ellipsoid_centre[0] = 1.0


def test_a_robot_without_a_model_file_is_refused():
    from idkit.robots.cylindrical import CylindricalRobot

    with pytest.raises(ValueError, match="geometry: needs a urdf or mjcf robot, got CylindricalRobot"):
        body_geometry(CylindricalRobot())


# --------------------------------------------------------------------------------------- MJCF
MJCF = """<mujoco model="shapes">
  <asset><mesh name="wedge" scale="2 1 1" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.3  0.1 0.1 0.3"/></asset>
  <worldbody>
    <body name="upper" pos="0.1 0.2 0.3" euler="10 -20 30">
      <joint name="shoulder" pos="0.02 -0.03 0.05" axis="0 0.6 0.8" ref="15"/>
      <geom name="arm" type="capsule" size="0.03 0.1" pos="0.05 0.02 0.1" euler="30 0 10"/>
      <geom name="skin" type="sphere" size="1" contype="0" conaffinity="0" mass="0"/>
      <body name="fore" pos="0.1 0 0.4" axisangle="1 0 0 30">
        <joint name="elbow" pos="0 0.01 0.02" axis="1 0 0"/>
        <body name="hand" pos="0 0.05 0.2" quat="0.9 0.1 0.2 0.3">
          <geom name="palm" type="box" size="0.02 0.03 0.04" pos="0.01 0.02 0.03" euler="5 10 15"/>
        </body>
      </body>
      <body name="side" pos="-0.1 0 0.3">
        <joint name="wrist" type="slide" axis="0 1 0"/>
        <geom name="w" type="mesh" mesh="wedge" pos="0.01 0.02 0.03" euler="0 0 90"/>
      </body>
    </body>
  </worldbody>
</mujoco>"""


@pytest.fixture(scope="module")
def shapes():
    pytest.importorskip("mujoco")
    robot = MJCFRobot(MJCF)
    return robot, body_geometry(robot)


def test_mjcf_geoms_sit_where_the_readers_inertials_put_them(shapes):
    """Each body's mass comes from one symmetric geom (the capsule; the box on a welded body), so the
    body's centre of mass from idkit's tree (joint ``pos``, ``ref``, welded ``quat`` …) is the geom's
    centre: the ellipsoid's, as both are centred on it. The non-colliding sphere is left out."""
    robot, geometry = shapes
    for body in ("upper", "fore"):
        _, com, _ = centroidal(robot.tree.bodies[robot.link_names.index(body)].inertial)
        np.testing.assert_allclose(geometry.bodies[body].ellipsoid_centre, com, atol=1e-6)
    assert geometry.bodies["upper"].sources == ("upper geom arm capsule",)
    assert geometry.bodies["fore"].sources == ("hand geom palm box",)


def test_an_mjcf_capsule_is_contained_whole(shapes):
    robot, geometry = shapes
    upper = geometry.bodies["upper"]
    # the capsule's pose in idkit's body frame: the MuJoCo body frame moved to the joint's pos
    rotation = Rotation.from_euler("XYZ", [30, 0, 10], degrees=True).as_matrix()
    translation = np.array([0.05, 0.02, 0.1]) - [0.02, -0.03, 0.05]
    points = surface("capsule", np.array([0.03, 0.1]), np.random.default_rng(0)) @ rotation.T + translation
    assert ellipsoid_values(upper.ellipsoid_centre, upper.ellipsoid_shape, points).max() <= 1 + 1e-9
    assert upper.in_ellipsoid(translation) and not upper.in_ellipsoid(translation + [0.2, 0, 0])


def test_an_mjcf_mesh_lands_where_the_file_put_it_though_mujoco_recentres_it(shapes):
    _, geometry = shapes
    vertices = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.3], [0.1, 0.1, 0.3]]) * [2, 1, 1]
    placed = vertices @ Rotation.from_euler("z", 90, degrees=True).as_matrix().T + [0.01, 0.02, 0.03]
    side = geometry.bodies["side"]
    np.testing.assert_allclose(
        [side.box_lo, side.box_hi], [placed.min(axis=0), placed.max(axis=0)], atol=1e-6
    )
    assert ellipsoid_values(side.ellipsoid_centre, side.ellipsoid_shape, placed).max() == pytest.approx(
        1.0, abs=1e-6
    )


def test_the_bundled_mjcf_arm_has_no_geometry_and_says_so():
    pytest.importorskip("mujoco")
    geometry = body_geometry(MJCFRobot("arm"))
    assert geometry.bodies == {"link1": None, "link2": None, "link3": None}
    assert geometry.summary() == "geometry bounds 0 of 3 bodies; no usable geometry on link1, link2, link3"


# --------------------------------------------------------------------------------------- KUKA
@pytest.mark.kuka
def test_the_kuka_collision_primitives_are_bounded_and_its_missing_meshes_named(kuka_dir, tmp_path):
    urdf = str(kuka_dir / "kuka_lwr4.urdf")
    geometry = body_geometry(URDFRobot(urdf))
    assert [name for name, body in geometry.bodies.items() if body is None] == ["lwr_6_link"]
    assert geometry.missing == (
        "lwr_6_link: collision mesh package://lwr_description/meshes/kuka/convex/arm_wrist_convex.stl (not found: give robot.package_dirs)",
        "lwr_6_link: visual mesh package://lwr_description/meshes/kuka/link_6.STL (not found: give robot.package_dirs)",
    )
    # lwr_1_link: spheres of 0.07 at the origin and at (0, 0.06, 0.2), a tilted cylinder between them
    first = geometry.bodies["lwr_1_link"]
    np.testing.assert_allclose(
        [first.box_lo, first.box_hi], [[-0.07, -0.07, -0.07], [0.07, 0.13, 0.27]], atol=1e-12
    )
    assert first.sources == ("lwr_1_link collision sphere",) * 2 + ("lwr_1_link collision cylinder",)
    for body in geometry.bodies.values():
        if (
            body is not None
        ):  # no larger than the box's own ellipsoid (the box holds the solids; 3 %: sampling)
            box_volume = np.prod(np.sqrt(3) * (body.box_hi - body.box_lo) / 2)
            assert np.linalg.det(body.ellipsoid_shape) ** -0.5 <= 1.03 * box_volume
    write_meshes(tmp_path / "lwr_description" / "meshes" / "kuka" / "convex")
    (tmp_path / "lwr_description" / "meshes" / "kuka" / "convex" / "cube.stl").rename(
        tmp_path / "lwr_description" / "meshes" / "kuka" / "convex" / "arm_wrist_convex.stl"
    )
    found = body_geometry(URDFRobot(urdf), package_dirs=[tmp_path])
    wrist = found.bodies["lwr_6_link"]
    assert wrist.sources == (
        "lwr_6_link collision mesh package://lwr_description/meshes/kuka/convex/arm_wrist_convex.stl",
    )
    np.testing.assert_allclose(
        [wrist.box_lo, wrist.box_hi], [[-1, -1, 0], [1, 1, 2]], atol=1e-9
    )  # turned by π about z


def test_unnamed_welded_mjcf_bodies_and_height_fields():
    """An unnamed welded body's geoms count (named by its index); a height field is the box from its
    base to its top elevation."""
    pytest.importorskip("mujoco")
    mjcf = """<mujoco><asset><hfield name="ground" nrow="2" ncol="2" size="0.3 0.2 0.1 0.05"/></asset>
      <worldbody><body name="b"><joint name="j" axis="0 0 1"/><geom type="sphere" size="0.1"/>
      <body pos="0 0 0.5"><geom type="sphere" size="0.1"/><geom name="relief" type="hfield" hfield="ground"/></body>
      <body name="tip" pos="0 0.5 0"><geom type="box" size="0.1 0.1 0.1"/></body></body></worldbody></mujoco>"""
    geometry = body_geometry(MJCFRobot(mjcf))
    body = geometry.bodies["b"]
    assert body.sources == (
        "b geom #0 sphere",
        "body #2 geom #1 sphere",
        "body #2 geom relief hfield",
        "tip geom #3 box",
    )
    np.testing.assert_allclose([body.box_lo, body.box_hi], [[-0.3, -0.2, -0.1], [0.3, 0.6, 0.6]])
    assert geometry.missing == ()


def test_a_placeholder_is_named_and_bounds_nothing():
    """A 1 cm box on a 1 kg link (it would be 370,000 kg/m³) is a placeholder: named, not a bound; a
    10 cm box on the same link is its shape, listed by name with what bounds it."""
    tiny = body_geometry(
        URDFRobot(one_link_urdf('<collision><geometry><box size="0.01 0.01 0.01"/></geometry></collision>'))
    )
    assert tiny.bodies["a"] is None
    assert tiny.placeholders == {
        "a": "collision box of 1 cm, far smaller than a body of its CAD mass 1 kg can be"
    }
    assert tiny.bounded_by() == {"a": f"nothing: {tiny.placeholders['a']}"}
    assert (
        tiny.summary()
        == f"geometry bounds 0 of 1 bodies; placeholder geometry, not used: a ({tiny.placeholders['a']})"
    )
    real = body_geometry(
        URDFRobot(one_link_urdf('<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision>'))
    )
    assert real.bodies["a"] is not None and not real.placeholders
    assert real.summary() == "geometry bounds 1 of 1 bodies; bounded: a (collision box)"


def test_a_package_folder_that_does_not_exist_is_refused_in_one_line(tmp_path):
    urdf = one_link_urdf('<collision><geometry><sphere radius="0.1"/></geometry></collision>')
    with pytest.raises(
        ValueError, match=r"^urdf: package_dirs names '/no/such/folder', which does not exist$"
    ):
        URDFRobot(urdf, package_dirs=["/no/such/folder"])
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(ValueError, match=r"which is a file, not a folder$"):
        URDFRobot(urdf, package_dirs=[str(tmp_path / "file.txt")])
    with pytest.raises(ValueError, match=r"^geometry: package_dirs names 'nowhere', which does not exist$"):
        body_geometry(URDFRobot(urdf), ["nowhere"])
    assert URDFRobot(urdf, package_dirs=[str(tmp_path)]).package_dirs == [str(tmp_path)]
