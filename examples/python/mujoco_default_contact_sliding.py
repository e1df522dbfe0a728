"""Does a MuJoCo contact hold a tool that slides along it? No controller of afs's involved.

A point mass (a sphere of 0.5 mm radius on two slide joints, gravity off) is pressed on a flat
box with 2.5 N (afs's preload) and pulled along it by a spring of 1 500 N/m and a damper of
100 N*s/m whose end moves at a constant speed, at MuJoCo's 0.1 ms step. The script prints the
fraction of steps without a contact (MuJoCo finds no penetration) once the mass slides, for
three masses and three speeds, on two contacts:

- `default`: the pair sets only its friction (mu = 0.67), as in
  examples/mujoco/user-arm-default-contact.xml: solref (0.02 1), solimp (0.9 0.95 0.001),
  the pyramidal cone and impratio 1 are MuJoCo's defaults;
- `afs example`: the contact of examples/mujoco/user-arm.xml (solimp d = 0.01, solref in the
  direct form, a friction damping, the elliptic cone with impratio 1e5).

docs/mujoco.md (*MuJoCo's default contact*) quotes its output.

    python3 examples/python/mujoco_default_contact_sliding.py
"""

import sys

MODEL = """<mujoco><option gravity="0 0 0" timestep="1e-4" {option}/><worldbody>
<body name="tool"><joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 1 0"/>
<inertial pos="0 0 0" mass="{mass}" diaginertia="1e-3 1e-3 1e-3"/>
<geom name="tip" type="sphere" size="0.0005" contype="0" conaffinity="0"/></body>
<body><geom name="face" type="box" size="0.25 0.02 0.05" pos="0 -0.0205 0" contype="0"
conaffinity="0"/></body></worldbody>
<contact><pair geom1="tip" geom2="face" condim="3" friction="0.67 0.67 0 0 0" {pair}/></contact>
</mujoco>"""

CONTACTS = {
    "default": ("", ""),
    "afs example": (
        'cone="elliptic" impratio="1e5"',
        'solimp="0.01 0.01 0.001 0.5 2" solref="-778.023 -3.89454" '
        'solreffriction="-0.389454 -0.389454"',
    ),
}
PRELOAD_N = 2.5
SPRING_N_PER_M = 1500.0
DAMPER_N_S_PER_M = 100.0


def lost_fraction(mujoco, contact, mass_kg, speed_m_per_s):
    """Fraction of steps without a contact between 1 s and 2 s (the pull starts at 0.5 s)."""
    option, pair = CONTACTS[contact]
    model = mujoco.MjModel.from_xml_string(MODEL.format(option=option, mass=mass_kg, pair=pair))
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    end, lost, steps = 0.0, 0, 0
    for i in range(int(2.0 / dt)):
        t = i * dt
        v = speed_m_per_s if t > 0.5 else 0.0
        end += v * dt
        data.qfrc_applied[0] = SPRING_N_PER_M * (end - data.qpos[0]) - DAMPER_N_S_PER_M * (
            data.qvel[0] - v
        )
        data.qfrc_applied[1] = -PRELOAD_N - DAMPER_N_S_PER_M * data.qvel[1]
        mujoco.mj_step(model, data)
        if t > 1.0:
            steps += 1
            lost += data.ncon == 0
    return lost / steps


def main() -> int:
    try:
        import mujoco
    except ImportError:
        print(
            "the Python package `mujoco` is missing; run "
            "`pip install -r examples/python/requirements.txt` first",
            file=sys.stderr,
        )
        return 2
    speeds = (0.001, 0.005, 0.02)
    print(f"mujoco {mujoco.__version__}: steps without contact while sliding")
    print("contact      | mass (kg) | " + " | ".join(f"{1e3 * v:g} mm/s" for v in speeds))
    for contact in CONTACTS:
        for mass in (0.3, 1.0, 3.0):
            row = [lost_fraction(mujoco, contact, mass, v) for v in speeds]
            print(f"{contact:12} | {mass:9} | " + " | ".join(f"{r:8.3f}" for r in row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
