//! The URDF loader: urdf-rs's robot -> [`HandModel`] (joint tree, limits, mimic, collision shapes,
//! fingertips, mesh fits), everything in f64 and converted to f32 at the end. The XML is
//! pre-scanned first (`xml_scan`); a link's `<collision>` elements become colliders in
//! `urdf_collision.rs`.

use super::*;

// ---------------------------------------------------------------------------------------------
// Loader internals. Everything is computed in f64 and converted to f32 at the end.

/// Turns a message into a one-line `anyhow::Error`, quoted values cut to [`MAX_QUOTED_CHARS`].
pub(super) fn one_line_error(msg: String) -> anyhow::Error {
    let msg = msg.replace('\r', "\n");
    let line: Vec<&str> = msg.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    anyhow::anyhow!("{}", clip_quoted(&line.join(" ")))
}

pub(super) type R<T> = std::result::Result<T, String>;

/// A rigid pose in f64.
#[derive(Clone, Copy, Debug)]
pub(super) struct DPose {
    pub(super) pos: DVec3,
    pub(super) rot: DQuat,
}

impl DPose {
    const IDENTITY: DPose = DPose { pos: DVec3::ZERO, rot: DQuat::IDENTITY };

    pub(super) fn mul(&self, o: &DPose) -> DPose {
        DPose { pos: self.pos + self.rot * o.pos, rot: (self.rot * o.rot).normalize() }
    }

    pub(super) fn to_pose(self) -> Pose {
        Pose::new(self.pos.as_vec3(), self.rot.as_quat().normalize())
    }
}

/// URDF rpy (fixed axes: roll about x, then pitch about y, then yaw about z):
/// R = Rz(yaw) · Ry(pitch) · Rx(roll).
fn rpy_to_quat(rpy: [f64; 3]) -> DQuat {
    (DQuat::from_rotation_z(rpy[2]) * DQuat::from_rotation_y(rpy[1]) * DQuat::from_rotation_x(rpy[0])).normalize()
}

pub(super) fn urdf_pose(p: &urdf_rs::Pose) -> DPose {
    DPose { pos: DVec3::from_array(p.xyz.0), rot: rpy_to_quat(p.rpy.0) }
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

pub(super) fn fmt3(v: &[f64; 3]) -> String {
    format!("{} {} {}", fnum(v[0]), fnum(v[1]), fnum(v[2]))
}

/// A number as a message shows it: plain, or in exponent form when huge or tiny (`1e300`, not
/// 301 digits).
pub(super) fn fnum(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}

fn pose_is_finite(p: &urdf_rs::Pose) -> bool {
    finite3(&p.xyz.0) && finite3(&p.rpy.0)
}

/// A finite `<origin>` whose `xyz` is within ±[`MAX_LENGTH_M`] and `rpy` within ±[`MAX_ANGLE_RAD`];
/// `owner` names the link or joint (and the file), `what` the element.
fn check_origin(owner: &str, what: &str, p: &urdf_rs::Pose) -> R<()> {
    if p.xyz.0.iter().any(|v| v.abs() > MAX_LENGTH_M) {
        return Err(format!("{owner} has {what} xyz {}; expected coordinates within ±{MAX_LENGTH_M} m", fmt3(&p.xyz.0)));
    }
    if p.rpy.0.iter().any(|v| v.abs() > MAX_ANGLE_RAD) {
        return Err(format!("{owner} has {what} rpy {}; expected angles within ±{MAX_ANGLE_RAD} rad", fmt3(&p.rpy.0)));
    }
    Ok(())
}

/// A name as a TOML key: bare where it can be (`joint_0`), quoted otherwise (`"joint_0.0"`).
fn toml_key(name: &str) -> String {
    if !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') { name.to_string() } else { format!("{name:?}") }
}

fn is_movable(j: &urdf_rs::Joint) -> bool {
    matches!(j.joint_type, urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous)
}

fn joint_type_name(t: &urdf_rs::JointType) -> &'static str {
    use urdf_rs::JointType::*;
    match t {
        Revolute => "revolute",
        Continuous => "continuous",
        Prismatic => "prismatic",
        Fixed => "fixed",
        Floating => "floating",
        Planar => "planar",
        Spherical => "spherical",
    }
}

/// Mass, centre of mass and inertia about the COM of one URDF link's `<inertial>`, expressed in a
/// merged link's frame.
struct MassPart {
    mass: f64,
    com: DVec3,
    inertia: DMat3,
}

fn combine_mass(parts: &[MassPart]) -> (f64, DVec3, DMat3) {
    let mass: f64 = parts.iter().map(|p| p.mass).sum();
    let com = if mass > 0.0 {
        parts.iter().map(|p| p.com * p.mass).sum::<DVec3>() / mass
    } else {
        DVec3::ZERO
    };
    let mut inertia = DMat3::ZERO;
    for p in parts {
        // parallel-axis theorem: I_com + m (|d|² E − d dᵀ)
        let d = p.com - com;
        let outer = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        inertia += p.inertia + (DMat3::from_diagonal(DVec3::splat(d.length_squared())) - outer) * p.mass;
    }
    let inertia = (inertia + inertia.transpose()) * 0.5;
    (mass, com, inertia)
}

pub(super) struct Loader<'a> {
    pub(super) file: String,
    pub(super) source: &'a Path,
    pub(super) opts: &'a HandLoadOptions,
    /// Names of the links that have an `<inertial>` element.
    pub(super) inertial_links: std::collections::HashSet<String>,
    /// Names of the joints that have a `<limit>` element.
    pub(super) limit_joints: std::collections::HashSet<String>,
    /// What each `<mesh>` collision became, in the order the colliders are read.
    pub(super) mesh_fits: std::cell::RefCell<Vec<MeshFitReport>>,
}

impl Loader<'_> {
    pub(super) fn build(&self, robot: &urdf_rs::Robot) -> R<HandModel> {
        let f = &self.file;
        let n = robot.links.len();
        if n == 0 {
            return Err(format!("{f} has no <link>; expected a hand whose root link is the palm"));
        }

        // ---- links
        let mut link_index: HashMap<&str, usize> = HashMap::new();
        for (i, l) in robot.links.iter().enumerate() {
            if link_index.insert(l.name.as_str(), i).is_some() {
                return Err(format!("link '{}' in {f} is defined twice; expected unique link names", l.name));
            }
            self.check_link(l)?;
        }

        // ---- joints and the tree structure
        let mut joint_index: HashMap<&str, usize> = HashMap::new();
        let mut parent_joint: Vec<Option<usize>> = vec![None; n];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut ends: Vec<(usize, usize)> = Vec::with_capacity(robot.joints.len());
        for (ji, j) in robot.joints.iter().enumerate() {
            let name = &j.name;
            if joint_index.insert(name.as_str(), ji).is_some() {
                return Err(format!("joint '{name}' in {f} is defined twice; expected unique joint names"));
            }
            if !matches!(
                j.joint_type,
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous | urdf_rs::JointType::Fixed
            ) {
                return Err(format!(
                    "joint '{name}' in {f} is {}; dextrain hands support revolute, continuous and fixed joints",
                    joint_type_name(&j.joint_type)
                ));
            }
            let lookup = |role: &str, link: &str| {
                link_index.get(link).copied().ok_or_else(|| {
                    format!(
                        "joint '{name}' in {f} references unknown {role} link '{link}'; expected the name of a <link> in the file"
                    )
                })
            };
            let p = lookup("parent", &j.parent.link)?;
            let c = lookup("child", &j.child.link)?;
            if p == c {
                return Err(format!(
                    "joint '{name}' in {f} connects link '{}' to itself; expected a tree of links (no loops)",
                    j.parent.link
                ));
            }
            if let Some(other) = parent_joint[c] {
                return Err(format!(
                    "link '{}' in {f} has two parent joints ('{}' and '{name}'); expected a tree (every link has at most one parent joint, no loops)",
                    j.child.link, robot.joints[other].name
                ));
            }
            if !pose_is_finite(&j.origin) {
                return Err(format!(
                    "joint '{name}' in {f} has a non-finite <origin> (xyz {}, rpy {}); expected finite numbers",
                    fmt3(&j.origin.xyz.0),
                    fmt3(&j.origin.rpy.0)
                ));
            }
            check_origin(&format!("joint '{name}' in {f}"), "<origin>", &j.origin)?;
            parent_joint[c] = Some(ji);
            children[p].push(ji);
            ends.push((p, c));
        }

        // joints named by hand.effort / hand.velocity tables are movable joints of this hand
        for (what, limit) in [("effort", &self.opts.effort), ("velocity", &self.opts.velocity)] {
            let Some(JointLimitOverride::PerJoint(m)) = limit else { continue };
            if let Some(bad) = m.keys().find(|k| !robot.joints.iter().any(|j| &j.name == *k && is_movable(j))) {
                let names: Vec<&str> = robot.joints.iter().filter(|j| is_movable(j)).map(|j| j.name.as_str()).collect();
                return Err(format!(
                    "key `hand.{what}.{bad}`: {f} has no movable joint '{bad}'; expected the name of one of its revolute or continuous joints ({})",
                    names.join(", ")
                ));
            }
        }

        let roots: Vec<usize> = (0..n).filter(|&i| parent_joint[i].is_none()).collect();
        if roots.is_empty() {
            return Err(format!(
                "{f} has no root link: every link has a parent joint, so the joints form a loop (e.g. through link '{}'); expected a tree rooted at the palm",
                robot.links[0].name
            ));
        }
        if roots.len() > 1 {
            let names: Vec<String> = roots.iter().map(|&i| format!("'{}'", robot.links[i].name)).collect();
            return Err(format!(
                "{f} has several root links ({}); expected exactly one link without a parent joint (the palm), every other link connected to it by joints",
                names.join(", ")
            ));
        }
        let root = roots[0];

        let movable: Vec<&urdf_rs::Joint> = robot.joints.iter().filter(|j| is_movable(j)).collect();
        if movable.len() > MAX_JOINTS {
            return Err(format!(
                "{f} has {} movable (revolute or continuous) joints, joint '{}' is number {}; expected at most {MAX_JOINTS} (MAX_JOINTS)",
                movable.len(),
                movable[MAX_JOINTS].name,
                MAX_JOINTS + 1
            ));
        }

        // ---- depth-first walk from the root: merged links, movable joints in topological order
        let mut place: Vec<Option<(usize, DPose)>> = vec![None; n];
        place[root] = Some((0, DPose::IDENTITY));
        let mut body_of: Vec<usize> = vec![root]; // merged link -> URDF link
        let mut joint_of: Vec<usize> = Vec::new(); // movable joint -> URDF joint
        let mut joints: Vec<Joint> = Vec::new();
        let mut stack: Vec<usize> = children[root].iter().rev().copied().collect();
        while let Some(ji) = stack.pop() {
            let j = &robot.joints[ji];
            let (p, c) = ends[ji];
            let (plink, ppose) = place[p].expect("a parent link is placed before its child joints");
            let origin = ppose.mul(&urdf_pose(&j.origin));
            if is_movable(j) {
                joints.push(self.movable_joint(j, plink, origin)?);
                joint_of.push(ji);
                body_of.push(c);
                place[c] = Some((joints.len(), DPose::IDENTITY));
            } else {
                place[c] = Some((plink, origin));
            }
            stack.extend(children[c].iter().rev().copied());
        }
        if let Some(i) = (0..n).find(|&i| place[i].is_none()) {
            return Err(format!(
                "link '{}' in {f} is not connected to the root link '{}' (its parent joints form a loop); expected a tree of links",
                robot.links[i].name, robot.links[root].name
            ));
        }

        // ---- mimic joints: resolve to the root leader
        let mut movable_of: HashMap<usize, usize> = HashMap::new(); // URDF joint -> movable joint
        for (mi, &ji) in joint_of.iter().enumerate() {
            movable_of.insert(ji, mi);
        }
        for (mi, &ji) in joint_of.iter().enumerate() {
            let j = &robot.joints[ji];
            let Some(m) = &j.mimic else { continue };
            let name = &j.name;
            let (mut mult, mut off) = self.mimic_coeffs(name, m)?;
            let mut leader_name = m.joint.as_str();
            let mut steps = 0;
            let leader = loop {
                let Some(&lj) = joint_index.get(leader_name) else {
                    return Err(format!(
                        "joint '{name}' in {f} mimics unknown joint '{leader_name}'; expected the name of a revolute or continuous joint"
                    ));
                };
                if lj == ji {
                    return Err(if steps == 0 {
                        format!("joint '{name}' in {f} mimics itself; expected <mimic joint> to name another revolute or continuous joint")
                    } else {
                        format!("joint '{name}' in {f} is part of a mimic cycle; expected mimic chains to end at a joint without <mimic>")
                    });
                }
                let lead = &robot.joints[lj];
                if !is_movable(lead) {
                    return Err(format!(
                        "joint '{name}' in {f} mimics joint '{leader_name}', which is {}; expected a revolute or continuous leader",
                        joint_type_name(&lead.joint_type)
                    ));
                }
                match &lead.mimic {
                    None => break movable_of[&lj],
                    Some(m2) => {
                        let (mult2, off2) = self.mimic_coeffs(&lead.name, m2)?;
                        // q = mult (mult2 q_leader2 + off2) + off
                        off += mult * off2;
                        mult *= mult2;
                        leader_name = m2.joint.as_str();
                        steps += 1;
                        if steps > robot.joints.len() {
                            return Err(format!(
                                "joint '{name}' in {f} has a mimic chain through joint '{}' that forms a cycle; expected mimic chains to end at a joint without <mimic>",
                                lead.name
                            ));
                        }
                    }
                }
            };
            if mult.abs() > MAX_MIMIC_MULTIPLIER || off.abs() > MAX_ANGLE_RAD {
                return Err(format!(
                    "joint '{name}' in {f} follows its root leader with multiplier {} and offset {} (composed along its mimic chain); expected |multiplier| <= {MAX_MIMIC_MULTIPLIER} and |offset| <= {MAX_ANGLE_RAD} rad",
                    fnum(mult),
                    fnum(off)
                ));
            }
            joints[mi].mimic = Some(Mimic { leader, multiplier: mult as f32, offset: off as f32 });
        }

        // ---- masses (merged), colliders, frames
        let nl = body_of.len();
        let mut parts: Vec<Vec<MassPart>> = (0..nl).map(|_| Vec::new()).collect();
        let mut colliders: Vec<Collider> = Vec::new();
        let mut frames: Vec<LinkFrame> = Vec::new();
        for (i, l) in robot.links.iter().enumerate() {
            let (li, lpose) = place[i].expect("every link is placed");
            if body_of[li] != i {
                frames.push(LinkFrame { name: l.name.clone(), link: li, pose: lpose.to_pose() });
            }
            let inr = &l.inertial;
            let ipose = lpose.mul(&urdf_pose(&inr.origin));
            let rot = DMat3::from_quat(ipose.rot);
            let t = &inr.inertia;
            let local = DMat3::from_cols(
                DVec3::new(t.ixx, t.ixy, t.ixz),
                DVec3::new(t.ixy, t.iyy, t.iyz),
                DVec3::new(t.ixz, t.iyz, t.izz),
            );
            parts[li].push(MassPart { mass: inr.mass.value, com: ipose.pos, inertia: rot * local * rot.transpose() });
            for (ci, c) in l.collision.iter().enumerate() {
                colliders.push(self.collider(l, ci, c, li, lpose)?);
            }
        }
        colliders.sort_by_key(|c| c.link);

        let links: Vec<Link> = body_of
            .iter()
            .zip(&parts)
            .map(|(&ui, parts)| {
                let (mass, com, inertia) = combine_mass(parts);
                let r = |k: usize| {
                    let row = inertia.row(k);
                    [row.x as f32, row.y as f32, row.z as f32]
                };
                Link { name: robot.links[ui].name.clone(), mass: mass as f32, com: com.as_vec3(), inertia: [r(0), r(1), r(2)] }
            })
            .collect();

        let root_name = &robot.links[root].name;
        if colliders.is_empty() {
            return Err(format!(
                "{f} has no collision shapes (root link '{root_name}'); expected at least one <collision> with a sphere, box, cylinder or capsule"
            ));
        }
        if colliders.len() > MAX_COLLIDERS {
            return Err(format!(
                "{f} has {} collision shapes, link '{}' holds number {}; expected at most {MAX_COLLIDERS} (MAX_COLLIDERS)",
                colliders.len(),
                links[colliders[MAX_COLLIDERS].link].name,
                MAX_COLLIDERS + 1
            ));
        }

        let mut model = HandModel {
            name: robot.name.clone(),
            source: self.source.to_path_buf(),
            links,
            joints,
            colliders,
            fingertips: Vec::new(),
            frames,
            warnings: Vec::new(),
            mesh_fits: self.mesh_fits.take(),
        };
        (model.fingertips, model.warnings) = self.fingertips(robot, &model)?;
        for fit in model.mesh_fits.iter().filter(|m| m.is_poor()) {
            model.warnings.push(format!(
                "{}: poor mesh fit: {} (more than {POOR_FIT_VOLUME_RATIO}× or {} mm); split the mesh into convex pieces or give the link primitive collision shapes",
                self.file,
                fit.describe(),
                POOR_FIT_GAP_M * 1e3
            ));
        }
        Ok(model)
    }

    fn check_link(&self, l: &urdf_rs::Link) -> R<()> {
        let f = &self.file;
        let name = &l.name;
        let inr = &l.inertial;
        if !pose_is_finite(&inr.origin) {
            return Err(format!("link '{name}' in {f} has a non-finite <inertial><origin>; expected finite numbers"));
        }
        let m = inr.mass.value;
        if !m.is_finite() {
            return Err(format!("link '{name}' in {f} has a non-finite mass ({m}); expected a finite mass >= 0 kg"));
        }
        if m < 0.0 {
            return Err(format!("link '{name}' in {f} has a negative mass ({m}); expected a mass >= 0 kg"));
        }
        // a link without <inertial> is a massless frame (urdf-rs reads it as mass 0, inertia 0)
        if self.inertial_links.contains(name.as_str()) && !(MIN_LINK_MASS_KG..=MAX_LINK_MASS_KG).contains(&m) {
            return Err(format!(
                "link '{name}' in {f} has <inertial><mass value> {}; expected a mass in [{MIN_LINK_MASS_KG}, {MAX_LINK_MASS_KG}] kg (leave <inertial> out for a massless frame)",
                fnum(m)
            ));
        }
        let t = &inr.inertia;
        let all = [t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz];
        if !all.iter().all(|x| x.is_finite()) {
            return Err(format!("link '{name}' in {f} has a non-finite <inertia>; expected finite numbers (kg·m²)"));
        }
        if t.ixx < 0.0 || t.iyy < 0.0 || t.izz < 0.0 {
            return Err(format!(
                "link '{name}' in {f} has a negative principal inertia (ixx {} iyy {} izz {}); expected ixx, iyy, izz >= 0",
                t.ixx, t.iyy, t.izz
            ));
        }
        for (attr, v) in ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"].iter().zip(all) {
            if v.abs() > MAX_INERTIA_KG_M2 {
                return Err(format!(
                    "link '{name}' in {f} has <inertia {attr}> {}; expected |{attr}| <= {MAX_INERTIA_KG_M2} kg·m²",
                    fnum(v)
                ));
            }
        }
        // positive semi-definite: every principal minor >= 0 (up to rounding, relative to the
        // largest moment s): ixx·iyy − ixy² ≥ 0, ixx·izz − ixz² ≥ 0, iyy·izz − iyz² ≥ 0, det ≥ 0
        let s = t.ixx.max(t.iyy).max(t.izz);
        let tol = 1e-6;
        let det = t.ixx * (t.iyy * t.izz - t.iyz * t.iyz) - t.ixy * (t.ixy * t.izz - t.iyz * t.ixz)
            + t.ixz * (t.ixy * t.iyz - t.iyy * t.ixz);
        let minors = [t.ixx * t.iyy - t.ixy * t.ixy, t.ixx * t.izz - t.ixz * t.ixz, t.iyy * t.izz - t.iyz * t.iyz];
        if minors.iter().any(|&m2| m2 < -tol * s * s) || det < -tol * s * s * s {
            return Err(format!(
                "link '{name}' in {f} has an <inertia> that is not positive semi-definite (ixx {} ixy {} ixz {} iyy {} iyz {} izz {}); expected a physical inertia tensor (ixx·iyy >= ixy², ixx·izz >= ixz², iyy·izz >= iyz², determinant >= 0)",
                fnum(t.ixx),
                fnum(t.ixy),
                fnum(t.ixz),
                fnum(t.iyy),
                fnum(t.iyz),
                fnum(t.izz)
            ));
        }
        check_origin(&format!("link '{name}' in {f}"), "<inertial><origin>", &inr.origin)?;
        for (ci, c) in l.collision.iter().enumerate() {
            if !pose_is_finite(&c.origin) {
                return Err(format!(
                    "link '{name}' in {f} has a non-finite <collision><origin> (collision {ci}); expected finite numbers"
                ));
            }
            check_origin(&format!("link '{name}' in {f}"), &format!("<collision><origin> (collision {ci})"), &c.origin)?;
        }
        Ok(())
    }

    fn mimic_coeffs(&self, joint: &str, m: &urdf_rs::Mimic) -> R<(f64, f64)> {
        let mult = m.multiplier.unwrap_or(1.0);
        let off = m.offset.unwrap_or(0.0);
        if !mult.is_finite() || !off.is_finite() {
            return Err(format!(
                "joint '{joint}' in {} has a non-finite <mimic> (multiplier {mult}, offset {off}); expected finite numbers",
                self.file
            ));
        }
        if mult.abs() > MAX_MIMIC_MULTIPLIER || off.abs() > MAX_ANGLE_RAD {
            return Err(format!(
                "joint '{joint}' in {} has <mimic multiplier=\"{}\" offset=\"{}\">; expected |multiplier| <= {MAX_MIMIC_MULTIPLIER} and |offset| <= {MAX_ANGLE_RAD} rad",
                self.file,
                fnum(mult),
                fnum(off)
            ));
        }
        Ok((mult, off))
    }

    fn movable_joint(&self, j: &urdf_rs::Joint, parent_link: usize, origin: DPose) -> R<Joint> {
        let f = &self.file;
        let name = &j.name;
        let axis = DVec3::from_array(j.axis.xyz.0);
        if !axis.is_finite() || axis.length() < 1e-9 || axis.abs().max_element() > MAX_AXIS_COMPONENT {
            return Err(format!(
                "joint '{name}' in {f} has axis ({}); expected a finite non-zero <axis xyz> with components within ±{MAX_AXIS_COMPONENT}",
                fmt3(&j.axis.xyz.0)
            ));
        }
        let lim = &j.limit;
        let continuous = j.joint_type == urdf_rs::JointType::Continuous;
        if !continuous && !self.limit_joints.contains(name.as_str()) {
            // urdf-rs reads a missing <limit> as lower = upper = 0: a locked joint. The config can
            // give effort and velocity, not position limits.
            return Err(format!(
                "joint '{name}' in {f} is revolute but has no <limit>; expected <limit lower upper effort velocity> on a revolute joint (hand.effort and hand.velocity in the config replace effort and velocity only; position limits come from the URDF)"
            ));
        }
        let (lower, upper) = if continuous {
            (f32::NEG_INFINITY, f32::INFINITY)
        } else {
            if !lim.lower.is_finite() || !lim.upper.is_finite() {
                return Err(format!(
                    "joint '{name}' in {f} has non-finite limits (lower {}, upper {}); expected finite <limit lower upper> (rad) on a revolute joint",
                    lim.lower, lim.upper
                ));
            }
            for (what, v) in [("lower", lim.lower), ("upper", lim.upper)] {
                if v.abs() > MAX_ANGLE_RAD {
                    return Err(format!(
                        "joint '{name}' in {f} has <limit {what}> {}; expected a revolute limit within ±{MAX_ANGLE_RAD} rad",
                        fnum(v)
                    ));
                }
            }
            if lim.lower > lim.upper {
                return Err(format!(
                    "joint '{name}' in {f} has lower limit {} > upper limit {}; expected lower <= upper",
                    lim.lower, lim.upper
                ));
            }
            (lim.lower as f32, lim.upper as f32)
        };
        // effort and velocity: the config's override where it names this joint, else the URDF's
        let mut limits = [0.0f32; 2];
        for (k, (what, urdf, over, unit, max)) in [
            ("effort", lim.effort, &self.opts.effort, "N·m", MAX_EFFORT_NM),
            ("velocity", lim.velocity, &self.opts.velocity, "rad/s", MAX_VELOCITY_RAD_S),
        ]
        .into_iter()
        .enumerate()
        {
            if let Some(v) = over.as_ref().and_then(|o| o.get(name)) {
                let v = f64::from(v);
                if !(v.is_finite() && v > 0.0 && v <= max) {
                    return Err(format!(
                        "joint '{name}' in {f}: hand.{what} gives it {what} limit {}; expected a positive finite limit of at most {max} {unit}",
                        fnum(v)
                    ));
                }
                limits[k] = v as f32;
                continue;
            }
            let fix = format!(
                "or set hand.{what} = <{unit}> (all joints) or hand.{what}.{} = <{unit}> in the config",
                toml_key(name)
            );
            if !(urdf.is_finite() && urdf > 0.0) {
                return Err(format!(
                    "joint '{name}' in {f} has {what} limit {}{}; expected a positive finite <limit {what}> ({unit}) on a movable joint, {fix}",
                    fnum(urdf),
                    if urdf == 0.0 { " (a missing <limit> or attribute reads as 0)" } else { "" }
                ));
            }
            if urdf > max {
                return Err(format!(
                    "joint '{name}' in {f} has {what} limit {}; expected a <limit {what}> of at most {max} {unit}, {fix}",
                    fnum(urdf)
                ));
            }
            limits[k] = urdf as f32;
        }
        let (damping, friction) = j.dynamics.as_ref().map_or((0.0, 0.0), |d| (d.damping, d.friction));
        for (what, v) in [("damping", damping), ("friction", friction)] {
            if !(v.is_finite() && (0.0..=MAX_DAMPING).contains(&v)) {
                return Err(format!(
                    "joint '{name}' in {f} has <dynamics {what}> {}; expected a finite number in [0, {MAX_DAMPING}]",
                    fnum(v)
                ));
            }
        }
        Ok(Joint {
            name: name.clone(),
            parent_link,
            origin: origin.to_pose(),
            axis: axis.normalize().as_vec3(),
            lower,
            upper,
            effort: limits[0],
            velocity: limits[1],
            damping: damping as f32,
            friction: friction as f32,
            mimic: None,
            continuous,
        })
    }

    fn fingertips(&self, robot: &urdf_rs::Robot, model: &HandModel) -> R<(Vec<Fingertip>, Vec<String>)> {
        let f = &self.file;
        let detect = self.opts.fingertips.is_empty();
        let mut tips: Vec<Fingertip> = Vec::new();
        if detect {
            let mut found = Vec::new();
            for l in robot.links.iter().filter(|l| l.name.to_ascii_lowercase().contains("tip")) {
                let (link, pose) = model.frame(&l.name).expect("every URDF link resolves to a frame");
                found.push(Fingertip { name: l.name.clone(), link, pos: pose.pos });
            }
            // several on one finger chain (`tip` and `tip_head` frames of one finger): the most
            // distal one, i.e. none lies on a link below it, or farther from the origin of the same
            // link (the joint); among equally far ones on one link, the first in URDF order
            const SAME: f32 = 1e-9;
            let distal = |i: usize| {
                let a = &found[i];
                !found.iter().enumerate().any(|(k, b)| {
                    if b.link != a.link {
                        model.is_ancestor_or_same(a.link, b.link)
                    } else {
                        let (da, db) = (a.pos.length(), b.pos.length());
                        db > da + SAME || (k < i && (db - da).abs() <= SAME)
                    }
                })
            };
            tips = (0..found.len()).filter(|&i| distal(i)).map(|i| found[i].clone()).collect();
        } else {
            for (i, spec) in self.opts.fingertips.iter().enumerate() {
                let name = spec.name();
                if self.opts.fingertips[..i].iter().any(|o| o.name() == name) {
                    return Err(format!(
                        "fingertip '{name}' in {f} is named twice (hand.fingertips[{i}]); expected distinct fingertip names (two tips on one link need distinct `name`s)"
                    ));
                }
                let tip = match spec {
                    FingertipSpec::Frame(frame) => {
                        let Some((link, pose)) = model.frame(frame) else {
                            return Err(format!(
                                "fingertip '{frame}' does not exist in {f}; expected the name of a link (frame) of the hand"
                            ));
                        };
                        Fingertip { name: name.to_string(), link, pos: pose.pos }
                    }
                    FingertipSpec::Link(t) => {
                        let Some((link, pose)) = model.frame(&t.link) else {
                            return Err(format!(
                                "fingertip '{name}' (hand.fingertips[{i}]) is on link '{}', which does not exist in {f}; expected the name of a link (frame) of the hand",
                                t.link
                            ));
                        };
                        let offset = Vec3::from_array(t.offset);
                        if !offset.is_finite() || offset.abs().max_element() as f64 > MAX_LENGTH_M {
                            return Err(format!(
                                "fingertip '{name}' (hand.fingertips[{i}]) in {f} has offset {offset}; expected a finite offset within ±{MAX_LENGTH_M} m in the frame of link '{}'",
                                t.link
                            ));
                        }
                        // the frame's pose in its rigid link ∘ the offset in the frame
                        Fingertip { name: name.to_string(), link, pos: pose.transform_point(offset) }
                    }
                };
                tips.push(tip);
            }
        }
        let names = |v: &mut dyn Iterator<Item = &str>| v.map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ");
        let tip_names = names(&mut tips.iter().map(|t| t.name.as_str()));
        if tips.len() > MAX_TIPS {
            return Err(format!(
                "{f} has {} fingertip frames ({tip_names}); expected at most {MAX_TIPS} (MAX_TIPS); name fewer in hand.fingertips",
                tips.len(),
            ));
        }
        let chains = model.finger_chains();
        let mut warnings = Vec::new();
        if tips.is_empty() || tips.len() != chains.len() {
            let found = if detect {
                if tips.is_empty() {
                    "no link name contains \"tip\", so no fingertips were found".to_string()
                } else {
                    format!("{} fingertips were found by name (links containing \"tip\": {tip_names})", tips.len())
                }
            } else {
                format!("hand.fingertips names {} fingertips ({tip_names})", tips.len())
            };
            let has = match chains.len() {
                0 => "no finger chains (no movable joints)".to_string(),
                n => format!("{n} finger chains (ending at links {})", names(&mut chains.iter().map(|&l| model.links[l].name.as_str()))),
            };
            warnings.push(format!(
                "{f}: {found}, but the hand has {has}; name one fingertip per finger with hand.fingertips = [\"<frame>\", ...] or {{ link = \"<link>\", offset = [x, y, z] }} entries (offset in m, in the link's frame)"
            ));
        }
        Ok((tips, warnings))
    }
}
