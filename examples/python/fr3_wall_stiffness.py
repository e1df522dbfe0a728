#!/usr/bin/env python3
"""The FR3 cell's contact stiffness as the tool tip meets its wall (docs/franka-cell.md, *The cell*).

The arm is held at franky-sim's start pose with its gravity compensated, the wall is moved
into the tip by 0.5, 1 and 2 mm, and one `mj_forward` gives the contact force on the tool
(fr3_scene.WristSensor, noise-free), for each stiffness given (N/m).

    python3 examples/python/fr3_wall_stiffness.py [STIFFNESS ...]   # default: 1e4
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from franky_sim.mujoco_simulator import MujocoSimulator  # noqa: E402

import fr3_scene  # noqa: E402

GAP_M = 0.002  # the default wall's gap to the tip's surface


def main():
    stiffnesses = [float(a) for a in sys.argv[1:]] or [1e4]
    for k in stiffnesses:
        sim = MujocoSimulator()
        sim.init()
        robot = sim.add_robot()
        fr3_scene.add_tool(sim, 0.16, 0.005)
        part = fr3_scene.Part.wall([0.554, 0.007], [0.0, -1.0], 0.465, 0.005)
        part.build(sim)
        part.add_contact(sim, mujoco, k, 0.0, 0.3, 5.0)
        sim.start()
        m, d = sim.model, sim.data
        sensor = fr3_scene.WristSensor(1)
        sensor.attach(m, mujoco)
        previous = None
        for depth in (0.0005, 0.001, 0.002):
            for a, q in zip(robot._qpos_addrs, robot.initial_q):
                d.qpos[a] = q
            d.qvel[:] = 0.0
            mujoco.mj_forward(m, d)
            c, quat = part.face_pose(d.geom_xpos[part_tip(m)])
            d.mocap_pos[0] = c + np.array([0.0, -(GAP_M + depth), 0.0])
            d.mocap_quat[0] = quat
            mujoco.mj_forward(m, d)
            d.qfrc_applied[:] = d.qfrc_bias
            mujoco.mj_forward(m, d)
            f, _ = sensor.true_wrench(m, d, mujoco)
            push = -(d.site_xmat[sensor.site].reshape(3, 3) @ f)[1]  # along the normal (0, -1)
            slope = ""
            if previous is not None:
                slope = f"  incremental {(push - previous[1]) / (depth - previous[0]):.0f} N/m"
            print(f"k = {k:g} N/m, {depth * 1e3:.1f} mm in: {push:.3f} N{slope}")
            previous = (depth, push)
        sim.cleanup()


def part_tip(m):
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "afs_tool_tip")


if __name__ == "__main__":
    main()
