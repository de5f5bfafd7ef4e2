#!/usr/bin/env python3
"""MuJoCo 4.0's side of dextrain's contact-fidelity benchmark (issue 36): the five scenes of
`dextrain bench --contacts`, built from the `scenes` object of its JSON (sizes, masses, friction,
forces, ramps, thresholds: src/bench_contacts.rs defines them) and measured the same way. Prints one
JSON object on stdout.

    dextrain bench --contacts > dextrain.json
    /tmp/peers/venv/bin/python benches/contact_fidelity_mujoco.py dextrain.json > mujoco.json

benches/contact_fidelity.sh runs both and compares. MuJoCo runs with the options of the peer scene (../shared/peers/mujoco_hand.xml):
timestep 1/120 s, the implicitfast integrator, the Newton solver, its default soft contacts
(solref 0.02 1, solimp 0.9 0.95 0.001), the pyramidal friction cone, and a friction coefficient per
pair equal to both geoms' (the same on both, so MuJoCo's max and dextrain's mean agree).
"""
import json
import math
import sys

import mujoco
import numpy as np

G = 9.81
DT = 1.0 / 120.0
# MuJoCo's variants: its defaults (soft friction: a body under a sticking force below μN creeps),
# and with the elliptic cone and 4 no-slip iterations after the main solve (MuJoCo's own remedy)
VARIANTS = {"default": "", "elliptic_noslip": 'cone="elliptic" noslip_iterations="4"'}
OPTION = ""

# the scenes' constants: the `scenes` object of `dextrain bench --contacts`'s JSON (read in main)
SCENES = {}


def table_and_box(half, mass, mu, name="box"):
    """The start of a scene's MJCF: the options, the table and a free box resting on it (the
    caller adds its own bodies and closes <worldbody> and <mujoco>)."""
    return f"""
<mujoco>
  <compiler angle="radian"/>
  <option timestep="{DT}" integrator="implicitfast" solver="Newton" gravity="0 0 {-G}" {OPTION}/>
  <worldbody>
    <geom name="table" type="plane" size="1 1 0.01" friction="{mu} 0.005 0.0001"/>
    <body name="{name}" pos="0 0 {half[2]}">
      <freejoint/>
      <geom name="{name}" type="box" size="{half[0]} {half[1]} {half[2]}" mass="{mass}" friction="{mu} 0.005 0.0001"/>
    </body>"""


def box_scene(half, mass, mu):
    return table_and_box(half, mass, mu) + """
  </worldbody>
</mujoco>"""


def box_model(s):
    """A scene's box on the table: the model, its data and the box's body id."""
    m = mujoco.MjModel.from_xml_string(box_scene(s["half"], s["mass"], s["mu"]))
    return m, mujoco.MjData(m), m.body("box").id


def settle_pos(m, d, body, secs):
    while d.time < secs - 1e-9:
        mujoco.mj_step(m, d)
    return d.xpos[body].copy()


def slide():
    s = SCENES["slide"]
    m, d, b = box_model(s)
    p0 = settle_pos(m, d, b, s["settle_s"])
    onset = None
    while d.time < s["settle_s"] + s["duration_s"]:
        f = s["force_start"] + s["force_rate"] * (d.time - s["settle_s"])
        d.xfrc_applied[b, :3] = [f, 0.0, 0.0]  # at the centre of mass
        mujoco.mj_step(m, d)
        if np.linalg.norm(d.xpos[b][:2] - p0[:2]) > s["onset_mm"] * 1e-3:
            onset = f
            break
    expected = s["mu"] * s["mass"] * G
    return {"slip_force_n": onset, "expected_n": expected, "error": None if onset is None else onset / expected - 1.0}


def tilt():
    s = SCENES["tilt"]
    m, d, b = box_model(s)

    def set_angle(deg):
        a = math.radians(deg)
        m.opt.gravity[:] = [G * math.sin(a), 0.0, -G * math.cos(a)]  # the plane tilted by a about y

    set_angle(s["angle_start"])
    p0 = settle_pos(m, d, b, s["settle_s"])
    onset = None
    while d.time < s["settle_s"] + s["duration_s"]:
        ang = s["angle_start"] + s["angle_rate"] * (d.time - s["settle_s"])
        set_angle(ang)
        mujoco.mj_step(m, d)
        if np.linalg.norm(d.xpos[b][:2] - p0[:2]) > s["onset_mm"] * 1e-3:
            onset = ang
            break
    expected = math.degrees(math.atan(s["mu"]))
    return {"slip_angle_deg": onset, "expected_deg": expected, "error_deg": None if onset is None else onset - expected}


def tip():
    s = SCENES["tip"]
    m, d, b = box_model(s)
    settle_pos(m, d, b, s["settle_s"])
    # the push: horizontal, at push_height above the table, on the box's centre line
    lever = np.array([0.0, 0.0, s["push_height"] - s["half"][2]])
    onset = None
    while d.time < s["settle_s"] + s["duration_s"]:
        f = s["force_start"] + s["force_rate"] * (d.time - s["settle_s"])
        force = np.array([f, 0.0, 0.0])
        arm = d.xmat[b].reshape(3, 3) @ lever  # the point turns with the box
        d.xfrc_applied[b, :3] = force
        d.xfrc_applied[b, 3:] = np.cross(arm, force)
        mujoco.mj_step(m, d)
        up = d.xmat[b].reshape(3, 3)[:, 2]
        if math.degrees(math.acos(min(1.0, up[2]))) > s["onset_deg"]:
            onset = f
            break
    expected = s["mass"] * G * s["half"][0] / s["push_height"]  # m g (w/2) = F h about the front edge
    return {"tip_force_n": onset, "expected_n": expected, "error": None if onset is None else onset / expected - 1.0}


def rest():
    s = SCENES["rest"]
    m, d, b = box_model(s)
    p0 = settle_pos(m, d, b, s["settle_s"])
    drift = 0.0
    while d.time < s["settle_s"] + s["duration_s"]:
        mujoco.mj_step(m, d)
        drift = max(drift, float(np.linalg.norm(d.xpos[b] - p0)))
    return {"drift_mm": 1e3 * drift, "sink_mm": 1e3 * (s["half"][2] - float(d.xpos[b][2]))}


def gripper_scene(s, effort):
    L, r, h = s["finger_length"], s["tip_radius"], s["half"]
    x = h[0] + r  # a vertical finger's tip touches the cube's side
    palm_z = h[2] + L
    fingers = ""
    for name, sx, axis in (("l", 1.0, "0 1 0"), ("r", -1.0, "0 -1 0")):
        fingers += f"""
      <body name="finger_{name}" pos="{sx * x} 0 0" gravcomp="1">
        <joint name="j_{name}" type="hinge" axis="{axis}" range="-0.5 0.5" armature="{s['armature']}"/>
        <geom type="capsule" fromto="0 0 0 0 0 {-(L - r)}" size="0.004" mass="0.02" contype="0" conaffinity="0"/>
        <geom name="tip_{name}" type="sphere" pos="0 0 {-L}" size="{r}" mass="0.005" friction="{s['mu']} 0.005 0.0001"/>
      </body>"""
    acts = "".join(f'<position joint="j_{n}" kp="{s["kp"]}" kv="{s["kd"]}" forcerange="{-effort} {effort}"/>' for n in "lr")
    return table_and_box(h, s["mass"], s["mu"], "cube") + f"""
    <body name="palm" pos="0 0 {palm_z}" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1" range="-0.1 0.2"/>
      <geom type="box" size="0.05 0.02 0.01" pos="0 0 0.02" mass="0.2" contype="0" conaffinity="0"/>{fingers}
    </body>
  </worldbody>
  <actuator>
    <position joint="lift" kp="{s['wrist_kp']}" kv="{s['wrist_kd']}"/>
    {acts}
  </actuator>
</mujoco>"""


def squeeze():
    s = SCENES["squeeze"]
    out = []
    for force in s["forces"]:
        effort = force * s["finger_length"]  # τ = F L: the stall torque of a vertical finger pushing F
        m = mujoco.MjModel.from_xml_string(gripper_scene(s, effort))
        d = mujoco.MjData(m)
        cube, palm = m.body("cube").id, m.body("palm").id
        jl, jr = m.joint("j_l").qposadr[0], m.joint("j_r").qposadr[0]
        d.qpos[jl] = d.qpos[jr] = -s["open_rad"]
        mujoco.mj_forward(m, d)
        tips = {m.geom("tip_l").id, m.geom("tip_r").id}
        t_close, t_lift = s["close_s"], s["close_s"] + s["lift_s"]
        t_end = t_lift + s["hold_s"]
        peak, pens, forces, rel0 = 0.0, [], [], None
        while d.time < t_end - 1e-9:
            d.ctrl[0] = s["lift_m"] * min(max((d.time - t_close) / s["lift_s"], 0.0), 1.0)
            # the fingers' target: from open (−open_rad) to closed (+open_rad) over close_ramp_s
            d.ctrl[1] = d.ctrl[2] = s["open_rad"] * (2.0 * min(d.time / s["close_ramp_s"], 1.0) - 1.0)
            mujoco.mj_step(m, d)
            pen, fn = 0.0, []
            for i in range(d.ncon):
                c = d.contact[i]
                if {c.geom1, c.geom2} & tips and m.geom("cube").id in (c.geom1, c.geom2):
                    pen = max(pen, -c.dist)
                    f6 = np.zeros(6)
                    mujoco.mj_contactForce(m, d, i, f6)
                    fn.append(f6[0])
            peak = max(peak, pen)
            if d.time >= t_close and rel0 is None:
                rel0 = d.xpos[cube][2] - d.xpos[palm][2]
            if d.time >= t_end - 0.5:
                pens.append(pen)
                forces.append(np.mean(fn) if fn else 0.0)
        slip = (rel0 - (d.xpos[cube][2] - d.xpos[palm][2])) if rel0 is not None else None
        out.append({"force_n": force, "peak_penetration_mm": 1e3 * peak, "penetration_mm": 1e3 * float(np.mean(pens)),
                    "tip_force_n": float(np.mean(forces)), "slip_mm": None if slip is None else 1e3 * slip,
                    "lifted_mm": 1e3 * (float(d.xpos[cube][2]) - s["half"][2])})
    return out


def main():
    global OPTION
    if len(sys.argv) != 2:
        sys.exit("usage: contact_fidelity_mujoco.py DEXTRAIN_JSON (the output of `dextrain bench --contacts`)")
    with open(sys.argv[1]) as f:
        SCENES.update(json.loads(f.read().strip().splitlines()[-1])["scenes"])
    res = {"tool": "mujoco", "version": mujoco.__version__, "dt": DT, "scenes": SCENES}
    for name, option in VARIANTS.items():
        OPTION = option
        res[name] = {"option": option, "slide": slide(), "tilt": tilt(), "tip": tip(), "rest": rest(), "squeeze": squeeze()}
    json.dump(res, sys.stdout)
    print()


if __name__ == "__main__":
    main()
