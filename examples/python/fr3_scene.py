"""The FR3 cell's scene and its wrist sensor (issue 48, docs/franka.md, *The cell*).

The scene adds to franky-sim's FR3:
- a tool on the flange: a rod along the flange's z axis ending in a sphere whose centre is the
  tool tip (`--tool-length-m` from the flange, radius `--tip-radius-m`), massless;
- a wall standing on the table: its face passes through `--wall-at X Y` (base frame, m) with
  its outward normal `--wall-normal NX NY` (horizontal, towards the tool), at the height of the
  tip, with MuJoCo's contact (`--wall-solref`, MuJoCo's default 0.02 1: about 4 kN/m against
  the FR3 at its start pose, docs/franka.md) and Coulomb friction `--mu`.

Only the tool and the wall collide with each other (contype/conaffinity 2); the arm's own
meshes do not touch the wall, so every contact force on the tool is one the sensor feels.

The sensor sits between the flange and the tool (an Axia80 or a Net F/T on the flange): it
reads the wrench that what the tool touches applies to the tool (ATI's convention, and afs's),
in the flange's axes, the moment about
the flange, plus a bias drawn once and Gaussian noise each sample (afs's sensor model's
figures, `SensorParams::default`).
"""

import xml.etree.ElementTree as ET

import numpy as np

TOOL_GROUP = "2"
FLANGE_OFFSET_M = 0.107  # fr3_link7 to the flange (franka_description's joint8)


def add_tool(sim, length_m, tip_radius_m, prefix="robot0_"):
    """A massless rod and tip sphere on the flange, and a site at the flange."""
    link7 = next(b for b in sim.worldbody.iter("body") if b.get("name") == prefix + "fr3_link7")
    flange = FLANGE_OFFSET_M
    ET.SubElement(link7, "site", name="afs_flange", pos=f"0 0 {flange}", size="0.005")
    common = dict(contype=TOOL_GROUP, conaffinity=TOOL_GROUP, density="0", condim="3")
    ET.SubElement(
        link7,
        "geom",
        name="afs_tool_rod",
        type="capsule",
        fromto=f"0 0 {flange} 0 0 {flange + length_m - tip_radius_m}",
        size=f"{0.8 * tip_radius_m}",
        rgba="0.8 0.6 0.2 1",
        **common,
    )
    ET.SubElement(
        link7,
        "geom",
        name="afs_tool_tip",
        type="sphere",
        pos=f"0 0 {flange + length_m}",
        size=f"{tip_radius_m}",
        rgba="0.9 0.2 0.2 1",
        **common,
    )


def add_wall(sim, at_m, normal, top_z_m, solref, mu):
    """A static box whose face passes through `at_m` (x, y) with outward normal `normal`."""
    n = np.array([normal[0], normal[1]], dtype=float)
    n /= np.linalg.norm(n)
    half = np.array([0.25, 0.02, 0.04])  # along the face, thickness, height
    centre = np.array(at_m, dtype=float) - n * half[1]
    yaw = np.arctan2(n[1], n[0]) - np.pi / 2  # the box's y axis along the normal
    ET.SubElement(
        sim.worldbody,
        "geom",
        name="afs_wall",
        type="box",
        size=" ".join(f"{v}" for v in half),
        pos=f"{centre[0]} {centre[1]} {top_z_m - half[2]}",
        euler=f"0 0 {yaw}",
        contype=TOOL_GROUP,
        conaffinity=TOOL_GROUP,
        condim="3",
        friction=f"{mu} 0.005 0.0001",
        solref=f"{solref[0]} {solref[1]}",
        rgba="0.3 0.5 0.8 1",
    )


class WristSensor:
    """The wrench on the tool, at the flange, in the flange's axes."""

    def __init__(self, seed, noise_force_n=0.02, noise_torque_nm=0.0005, bias_force_n=0.05, bias_torque_nm=0.002):
        self.rng = np.random.default_rng(seed)
        self.noise = np.array([noise_force_n] * 3 + [noise_torque_nm] * 3)
        self.bias = self.rng.uniform(-1.0, 1.0, 6) * np.array([bias_force_n] * 3 + [bias_torque_nm] * 3)
        self.tool = None
        self.site = None
        self.f6 = np.zeros(6)

    def attach(self, model, mujoco):
        self.tool = {
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name) for name in ("afs_tool_rod", "afs_tool_tip")
        }
        self.site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "afs_flange")

    def true_wrench(self, model, data, mujoco):
        """The wrench without noise or bias: (force N, moment N·m) in the flange's axes."""
        force = np.zeros(3)
        moment = np.zeros(3)
        flange = data.site_xpos[self.site]
        for i in range(data.ncon):
            c = data.contact[i]
            # mj_contactForce gives the force on geom2, along the normal from geom1 to geom2
            # (checked: a tip pressed into the wall reads the wall's push on it).
            if c.geom1 in self.tool:
                sign = -1.0
            elif c.geom2 in self.tool:
                sign = 1.0
            else:
                continue
            mujoco.mj_contactForce(model, data, i, self.f6)
            f = sign * (c.frame.reshape(3, 3).T @ self.f6[:3])
            force += f
            moment += np.cross(c.pos - flange, f)
        r = data.site_xmat[self.site].reshape(3, 3)
        return r.T @ force, r.T @ moment

    def reading(self, model, data, mujoco):
        f, m = self.true_wrench(model, data, mujoco)
        return np.concatenate([f, m]) + self.bias + self.rng.normal(0.0, 1.0, 6) * self.noise
