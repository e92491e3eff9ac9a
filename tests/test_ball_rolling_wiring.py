"""Wiring of the ball-rolling diagram (diagrams/ball_rolling.py): what reads what."""
import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from adaptive_c3.diagrams.ball_rolling import build_ball_rolling_diagram
from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.systems.perception.ball_detector import BallDetector
from adaptive_c3.systems.perception.ball_pose_sensor import BallPoseSensor
from adaptive_c3.systems.rolling.estimator import BallRollingEstimator

SCENARIO = SCENARIO_DIR / "ball_rolling.yaml"


def _scenario(*overrides):
    return load_scenario(SCENARIO, ["robot=point_ee", *overrides])[0]


def _build(*overrides):
    return build_ball_rolling_diagram(_scenario(*overrides))


def _sources(diagram):
    """{(reading system, input port name): (source system, output port name)}."""
    out = {}
    for (sys_in, i), (sys_out, o) in diagram.connection_map().items():
        out[(sys_in, sys_in.get_input_port(i).get_name())] = (
            sys_out, sys_out.get_output_port(o).get_name())
    return out


def _estimator_ball_sources(diagram):
    src = _sources(diagram)
    est = [s for s in diagram.GetSystems() if isinstance(s, BallRollingEstimator)]
    assert len(est) == 1
    return {name: src[(est[0], name)] for name in ("ball.position", "ball.velocity")}


def check_camera_wiring(d):
    """Camera on: the estimator's ball inputs come from the Hough detector, which reads
    only the camera image; no pose sensor (the true pose plus noise) is in the diagram,
    and nothing but loggers reads the plant's ball state."""
    for sys_, _ in _estimator_ball_sources(d.diagram).values():
        assert isinstance(sys_, BallDetector), type(sys_).__name__
    assert not any(isinstance(s, BallPoseSensor) for s in d.diagram.GetSystems())
    for (sys_in, name), (sys_out, out_name) in _sources(d.diagram).items():
        if isinstance(sys_in, BallDetector):
            assert name == "camera.color_image"
        if sys_out is d.plant and out_name == "ball_state":
            assert sys_in.get_name().startswith("log_"), sys_in.get_name()


def test_camera_on_estimator_reads_only_the_detector():
    check_camera_wiring(_build("camera.enabled=true"))


def test_camera_check_fails_on_the_camera_off_diagram():
    """The same check on the camera-off diagram (true pose plus noise) must fail."""
    with pytest.raises(AssertionError):
        check_camera_wiring(_build("camera.enabled=false"))


def _first_lcs_c3_plans_with(r):
    """Run the camera-off diagram (learner off, r_comp held at r) until C3 first solves;
    the LCS that solve received."""
    d = _build("camera.enabled=false", "learner.enabled=false")
    seen = []
    for solver in (d.planner._roll, d.planner._ret):
        plain = solver.solve

        def solve(lcs, *a, _plain=plain, **kw):
            seen.append(lcs)
            return _plain(lcs, *a, **kw)
        solver.solve = solve
    sim = Simulator(d.diagram)
    ctx = d.learner.GetMyMutableContextFromRoot(sim.get_mutable_context())
    ctx.get_mutable_discrete_state(0).get_mutable_value()[:len(r)] = r
    assert np.array_equal(d.learner.residual(ctx), r)
    t = 0.0
    while not seen and t < 3.0:
        t += 0.05
        sim.AdvanceTo(t)
    assert seen, "C3 never solved in 3 s"
    return seen[0]


def test_r_comp_reaches_the_lcs_c3_plans_with():
    """A residual with zero mean on the EE-ball rows leaves the gait (which reads the
    mean gap) unchanged, so both runs reach their first C3 solve in the same state: the
    LCSs C3 received differ in c by exactly r rescaled from the learner's step to the
    planning dt (r dt_learn / dt_plan: both carry the same gap r dt), and nowhere else."""
    r = np.array([0.01, -0.01, 0.02, -0.02, 0.03, -0.03, 0.005, -0.005])
    base = _first_lcs_c3_plans_with(np.zeros(8))
    with_r = _first_lcs_c3_plans_with(r)
    m = _scenario().model
    scale = (m.learner_dt or m.planning_dt) / m.planning_dt
    assert scale > 0
    np.testing.assert_allclose(with_r.c - base.c, r * scale, atol=1e-12)
    for name in ("A", "B", "D", "d", "E", "F", "H"):
        np.testing.assert_array_equal(getattr(with_r, name), getattr(base, name))


def test_camera_renders_a_twin_posed_like_the_plant():
    """Issue 18: the renderer sits on the camera's own SceneGraph (posed only when the
    camera renders), not on the plant's, which updates poses every 1 ms step. The twin
    draws each body's pieces of one colour as one mesh, and the triangles it renders are
    the plant's perception geometry's, where the plant's SceneGraph puts them."""
    from pydrake.geometry import Role

    from adaptive_c3.systems.perception.merged_visuals import shape_triangles
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml", ["camera.enabled=true"])
    h = build_ball_rolling_diagram(s)
    camera_sg = next(sy for sy in h.diagram.GetSystems()
                     if sy.get_name() == "camera_scene_graph")
    assert h.scene_graph.RendererCount() == 0 and camera_sg.RendererCount() == 1
    ctx = h.diagram.CreateDefaultContext()
    pc = h.plant.GetMyMutableContextFromRoot(ctx)
    rng = np.random.default_rng(3)
    h.plant.SetPositions(pc, h.plant.GetPositions(pc) + 0.1 * rng.standard_normal(
        h.plant.num_positions()))
    triangles, counts = {}, {}
    for sg in (h.scene_graph, camera_sg):
        q = sg.get_query_output_port().Eval(sg.GetMyContextFromRoot(ctx))
        insp = q.inspector()
        ids = insp.GetAllGeometryIds(Role.kPerception)
        counts[sg.get_name()] = len(ids)
        world = []
        for g in ids:
            X = q.GetPoseInWorld(g)
            t = shape_triangles(insp.GetShape(g)).transformed(X.rotation().matrix(),
                                                               X.translation())
            # each triangle as its 3 vertices in a canonical (sorted) order
            world += [np.array(sorted(map(tuple, t.V[f]))).ravel() for f in t.F]
        triangles[sg.get_name()] = np.array(world)
    assert counts[h.scene_graph.get_name()] == 44 and counts["camera_scene_graph"] == 12
    from scipy.spatial import cKDTree
    a, b = triangles["camera_scene_graph"], triangles[h.scene_graph.get_name()]
    assert a.shape == b.shape
    for x, y in ((a, b), (b, a)):       # every triangle has a twin within 1 um
        dist, _ = cKDTree(y).query(x)
        assert dist.max() < 1e-6
