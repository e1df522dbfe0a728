"""The FR3 cell's scene and its wrist sensor (issue 48, docs/franka-cell.md, *The cell*).

The scene adds to franky-sim's FR3:
- a tool on the flange: a rod along the flange's z axis ending in a sphere whose centre is the
  tool tip (its length from the flange, `cell.toml`'s `tool_length_m` or `--tool-length-m`;
  radius `--tip-radius-m`), massless;
- the part ([`Part`]): the scenario's surface as `afs run` places it (`cell.toml`), or a flat
  wall (`--wall-at`, `--wall-normal`), with afs's MuJoCo contact recipe: a spring of the given
  stiffness and damping, and Coulomb friction on an elliptic cone.

Only the tool and the part collide with each other (contype/conaffinity 2); the arm's own
meshes do not touch the part, so every contact force on the tool is one the sensor feels.

The sensor sits between the flange and the tool (an Axia80 or a Net F/T on the flange): it
reads the wrench that what the tool touches applies to the tool (ATI's convention, and afs's),
in the flange's axes, the moment about the flange, plus a bias drawn once and Gaussian noise
each sample (afs's sensor model's figures, `SensorParams::default`).
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


class Part:
    """The part the tool meets: a surface given as points of the tip centre's path (base frame,
    increasing u, the material on the right of the direction of travel about `plane_normal`).

    Built as afs's own MuJoCo world builds it (docs/mujoco.md, *The model*): one box whose face
    is kept tangent to the surface at the point nearest the tip, sunk by the tip's radius, every
    step (a mocap body), so that the tip always meets exactly one face (chords or a height
    field would touch it in two places at once, each a full contact spring). The contact is a
    spring of `stiffness_n_per_m` (the explicit pair's solref in MuJoCo's direct form over
    solimp d = 0.01: `s0 = -k (1 - d) w`, w the tool body's translational inverse weight) with
    `damping_n_s_per_m`, and Coulomb friction `mu` on an elliptic cone whose sticking is a
    damper of `friction_damping_n_s_per_m`."""

    D = 0.01

    def __init__(self, points_m, plane_normal, tip_radius_m):
        self.points = np.asarray(points_m, dtype=float)
        self.plane_normal = np.asarray(plane_normal, dtype=float)
        self.radius = tip_radius_m
        self.mocap = None
        self.tip = None

    @classmethod
    def wall(cls, at_m, normal, z_m, tip_radius_m, half_length_m=0.25):
        """A flat wall whose face passes `tip_radius_m` beyond `at_m` (x, y), its outward
        normal `normal`, at height `z_m` (a horizontal plane, normal up)."""
        n = np.array([normal[0], normal[1], 0.0], dtype=float)
        n /= np.linalg.norm(n)
        up = np.array([0.0, 0.0, 1.0])
        t = np.cross(n, up)  # the material (−n) on the right of t about up
        centre = np.array([at_m[0], at_m[1], z_m]) + n * tip_radius_m
        return cls([centre - half_length_m * t, centre + half_length_m * t], up, tip_radius_m)

    def build(self, sim, half_thickness_m=0.02, half_height_m=0.04, half_length_m=0.02):
        body = ET.SubElement(sim.worldbody, "body", name="afs_part", mocap="true")
        self.half_thickness = half_thickness_m
        ET.SubElement(
            body,
            "geom",
            name="afs_face",
            type="box",
            size=f"{half_length_m} {half_thickness_m} {half_height_m}",
            contype=TOOL_GROUP,
            conaffinity=TOOL_GROUP,
            rgba="0.3 0.5 0.8 1",
        )
        p, q = self.face_pose(self.points[0])
        body.set("pos", " ".join(f"{v}" for v in p))
        body.set("quat", " ".join(f"{v}" for v in q))

    def add_contact(self, sim, mujoco, stiffness_n_per_m, damping_n_s_per_m, mu, friction_damping_n_s_per_m):
        """The tip–face pair, its spring set from the compiled model's inverse weight."""
        model = mujoco.MjModel.from_xml_string(ET.tostring(sim.scene, encoding="unicode"))
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot0_fr3_link7")
        w = float(model.body_invweight0[body][0])
        scale = (1.0 - self.D) * w
        option = sim.scene.find("option")
        if option is None:
            option = ET.SubElement(sim.scene, "option")
        option.set("cone", "elliptic")
        option.set("impratio", "1e5")
        contact = sim.scene.find("contact")
        if contact is None:
            contact = ET.SubElement(sim.scene, "contact")
        ET.SubElement(
            contact,
            "pair",
            geom1="afs_tool_tip",
            geom2="afs_face",
            condim="3",
            friction=f"{mu} {mu} 0 0 0",
            solimp=f"{self.D} {self.D} 0.001 0.5 2",
            solref=f"{-stiffness_n_per_m * scale} {-damping_n_s_per_m * scale}",
            solreffriction=f"{-friction_damping_n_s_per_m * scale} {-friction_damping_n_s_per_m * scale}",
        )

    def nearest(self, p):
        """The point of the path nearest `p`, and the path's unit tangent there."""
        a, b = self.points[:-1], self.points[1:]
        d = b - a
        length2 = np.einsum("ij,ij->i", d, d)
        s = np.clip(np.einsum("ij,ij->i", p - a, d) / length2, 0.0, 1.0)
        c = a + d * s[:, None]
        i = int(np.argmin(np.einsum("ij,ij->i", p - c, p - c)))
        return c[i], d[i] / np.sqrt(length2[i])

    def face_pose(self, p, tangent=None):
        """The face box's centre and quaternion (w, x, y, z) for the path point `p`."""
        if tangent is None:
            p, tangent = self.nearest(p)
        out = np.cross(self.plane_normal, tangent)
        centre = p - out * (self.radius + self.half_thickness)
        r = np.column_stack([tangent, out, np.cross(tangent, out)])
        q = np.zeros(4)
        mujoco_quat(q, r)
        return centre, q

    def update(self, sim, mujoco):
        """Before each step: the face tangent at the point nearest the tip."""
        if self.mocap is None:
            body = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, "afs_part")
            self.mocap = int(sim.model.body_mocapid[body])
            self.tip = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_GEOM, "afs_tool_tip")
        c, q = self.face_pose(sim.data.geom_xpos[self.tip])
        sim.data.mocap_pos[self.mocap] = c
        sim.data.mocap_quat[self.mocap] = q


def mujoco_quat(q, r):
    """The quaternion (w, x, y, z) of the rotation matrix `r` (without MuJoCo, for the scene
    before it is compiled)."""
    t = np.trace(r)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q[:] = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s


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
