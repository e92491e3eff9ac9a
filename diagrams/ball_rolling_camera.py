"""The ball-rolling experiment's overhead camera and Hough detector (recipe step 3):
a twin of the true world in a SceneGraph of its own -> RgbdSensor -> BallDetector.
"""
from __future__ import annotations

from adaptive_c3.diagrams.ball_rolling_world import ball_start_xy, true_world
from adaptive_c3.scenarios.ball_rolling_schema import BallRollingScenario
from adaptive_c3.systems.perception.camera import overhead_camera_spec


def _add_camera_scene_graph(builder, add_world, time_step: float):
    """A SceneGraph only the camera reads: a twin of the plant's bodies and geometry
    (add_world(twin)), posed by MultibodyPositionToGeometryPose from a multibody state.
    Returns (scene_graph, to_pose); the caller connects to_pose's input.

    A SceneGraph moves every geometry in each of its render engines whenever its poses
    are updated. On the plant's own SceneGraph that is every 1 ms plant step (contact
    needs the poses), and with the renderer there a step cost 90 us instead of 9 us
    (measured on this diagram): a renderer's share paid at 1 kHz for a camera at 80 Hz.
    The twin's poses are computed only when the camera evaluates its query port, so
    only at the camera's rate. Same geometry, same poses: the same image. Each body's
    visual pieces of one colour are drawn as one mesh (merged_visuals.py: the renderer's
    cost is per piece, and the Panda has 42)."""
    from pydrake.geometry import SceneGraph
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.systems.rendering import MultibodyPositionToGeometryPose

    from adaptive_c3.systems.perception.merged_visuals import merge_body_visuals
    camera_sg = builder.AddSystem(SceneGraph())
    camera_sg.set_name("camera_scene_graph")
    twin = MultibodyPlant(time_step)
    twin.RegisterAsSourceForSceneGraph(camera_sg)
    add_world(twin)
    merge_body_visuals(twin, camera_sg)
    twin.Finalize()
    to_pose = builder.AddSystem(MultibodyPositionToGeometryPose(twin, input_multibody_state=True))
    builder.Connect(to_pose.get_output_port(), camera_sg.get_source_pose_port(twin.get_source_id()))
    return camera_sg, to_pose


def add_ball_camera(builder, plant, s: BallRollingScenario):
    """Adds the overhead camera and the detector for `plant` (finalized, the true world
    of s); returns the BallDetector ("ball.position" / "ball.velocity" /
    "ball.detection_ok" outputs)."""
    from adaptive_c3.systems.perception.ball_detector import BallDetector
    from adaptive_c3.systems.perception.camera import add_overhead_camera
    camera_sg, to_pose = _add_camera_scene_graph(builder, true_world(s), plant.time_step())
    builder.Connect(plant.get_state_output_port(), to_pose.get_input_port())
    spec = overhead_camera_spec(target=(s.target.center[0], s.target.center[1], 0.0),
                                width=s.camera.width, height=s.camera.height)
    sensor, spec = add_overhead_camera(builder, camera_sg, spec)
    # The detector back-projects onto the plane z = R_MODEL: it only knows the model.
    det = builder.AddSystem(BallDetector(spec, ball_radius=s.model.ball_radius,
                                         period=1.0 / s.camera.rate_hz,
                                         initial_position_xy=tuple(ball_start_xy(s))))
    builder.Connect(sensor.color_image_output_port(), det.GetInputPort("camera.color_image"))
    return det
