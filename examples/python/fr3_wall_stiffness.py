#!/usr/bin/env python3
"""The FR3 cell's wall stiffness as the tool tip meets it (docs/franka.md, *The cell*).

The arm is held at franky-sim's start pose with its gravity compensated, the wall is moved
into the tip by 0.5, 1 and 2 mm, and one `mj_forward` gives the contact force on the tool
(fr3_scene.WristSensor, noise-free), for each MuJoCo time constant given.

    python3 examples/python/fr3_wall_stiffness.py [TIMECONST ...]   # default: 0.02 (MuJoCo's)
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
    constants = [float(a) for a in sys.argv[1:]] or [0.02]
    for tc in constants:
        sim = MujocoSimulator()
        sim.init()
        robot = sim.add_robot()
        fr3_scene.add_tool(sim, 0.16, 0.005)
        fr3_scene.add_wall(sim, [0.554, 0.007], [0.0, -1.0], 0.465 + 0.04, (tc, 1.0), 0.3)
        sim.start()
        m, d = sim.model, sim.data
        sensor = fr3_scene.WristSensor(1)
        sensor.attach(m, mujoco)
        wall = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "afs_wall")
        base = m.geom_pos[wall].copy()
        previous = None
        for depth in (0.0005, 0.001, 0.002):
            m.geom_pos[wall][1] = base[1] - (GAP_M + depth)
            d.qvel[:] = 0.0
            for a, q in zip(robot._qpos_addrs, robot.initial_q):
                d.qpos[a] = q
            mujoco.mj_forward(m, d)
            d.qfrc_applied[:] = d.qfrc_bias
            mujoco.mj_forward(m, d)
            f, _ = sensor.true_wrench(m, d, mujoco)
            push = -(d.site_xmat[sensor.site].reshape(3, 3) @ f)[1]  # along the normal (0, -1)
            slope = ""
            if previous is not None:
                slope = f"  incremental {(push - previous[1]) / (depth - previous[0]):.0f} N/m"
            print(f"timeconst {tc} s, {depth * 1e3:.1f} mm in: {push:.2f} N{slope}")
            previous = (depth, push)
            m.geom_pos[wall][:] = base
        sim.cleanup()


if __name__ == "__main__":
    main()
