//! The MCAP side of the reference format: frames from and to JSON messages.

use super::*;

pub(super) fn describe(v: &json::Value) -> String {
    use json::Value::*;
    match v {
        Null => "null".into(),
        Bool(b) => format!("the boolean {b}"),
        Num(t) => format!("the number {t}"),
        Str(s) => format!("the string {:?}", truncate(s)),
        Arr(items) => format!("an array with {} elements", items.len()),
        Obj(_) => "an object".into(),
    }
}

pub(super) fn expect_obj<'v>(v: &'v json::Value, field: &str, expected: &str) -> Result<&'v [(String, json::Value)], String> {
    match v {
        json::Value::Obj(entries) => Ok(entries),
        json::Value::Null => {
            Err(format!("field `{field}`: expected {expected} (leave the key out instead of null), got null"))
        }
        other => Err(format!("field `{field}`: expected {expected}, got {}", describe(other))),
    }
}

pub(super) fn expect_num<'v>(v: &'v json::Value, field: &str) -> Result<&'v str, String> {
    match v {
        json::Value::Num(t) => Ok(t),
        other => Err(format!("field `{field}`: expected a number, got {}", describe(other))),
    }
}

/// The number texts of an object with exactly the keys `keys`.
pub(super) fn keyed_numbers<'v, const N: usize>(
    v: &'v json::Value,
    field: &str,
    keys: &[&str; N],
) -> Result<[&'v str; N], String> {
    let expected = format!("an object with the numbers {}", keys.join(", "));
    let entries = expect_obj(v, field, &expected)?;
    let mut out: [Option<&str>; N] = [None; N];
    for (k, val) in entries {
        let Some(i) = keys.iter().position(|key| key == k) else {
            return Err(format!("field `{field}.{k}`: unknown key: expected only {}", keys.join(", ")));
        };
        out[i] = Some(expect_num(val, &format!("{field}.{k}"))?);
    }
    let mut texts = [""; N];
    for i in 0..N {
        texts[i] = out[i].ok_or_else(|| format!("field `{field}.{}`: missing: expected a number", keys[i]))?;
    }
    Ok(texts)
}

pub(super) fn pose_from_json(v: &json::Value, field: &str) -> Result<Pose, String> {
    let texts = keyed_numbers(v, field, &POSE_KEYS)?;
    let labels = POSE_KEYS.map(|k| format!("field `{field}.{k}`"));
    pose_from_texts(texts, &labels, &format!("field `{field}` (qx, qy, qz, qw)"))
}

pub(super) fn check_name(field: &str, name: &str) -> Result<(), String> {
    if is_valid_name(name) {
        Ok(())
    } else {
        Err(format!(
            "field `{field}`: name {name:?}: expected a non-empty name without whitespace, control characters, commas or double quotes"
        ))
    }
}

pub(super) fn raw_frame_from_json(v: &json::Value, loc: Loc) -> Result<RawFrame, String> {
    let entries = expect_obj(v, "message", "a JSON object with t, wrist, joints (and optionally fingertips, object)")
        .map_err(|e| e.replacen("field `message`", "message", 1))?;
    let get = |key: &str| entries.iter().find(|(k, _)| k == key).map(|(_, v)| v);
    if let Some((k, _)) = entries.iter().find(|(k, _)| !TOP_KEYS.contains(&k.as_str())) {
        return Err(format!("field `{k}`: unknown key: expected only {}", TOP_KEYS.join(", ")));
    }
    let required = |key: &str, what: &str| get(key).ok_or_else(|| format!("field `{key}`: missing: expected {what}"));

    let t = time(expect_num(required("t", "the time in s")?, "t")?, "field `t`")?;
    let wrist = pose_from_json(required("wrist", "the wrist pose")?, "wrist")?;
    let mut joints = Vec::new();
    for (name, val) in expect_obj(
        required("joints", "an object of joint positions by name")?,
        "joints",
        "an object of joint positions by name",
    )? {
        check_name("joints", name)?;
        let label = format!("field `joints.{name}`");
        joints.push((name.clone(), joint_value(expect_num(val, &format!("joints.{name}"))?, &label)?));
    }
    let fingertips = match get("fingertips") {
        None => None,
        Some(v) => {
            let mut tips = Vec::new();
            for (name, val) in expect_obj(v, "fingertips", "an object of fingertip positions by name")? {
                check_name("fingertips", name)?;
                let field = format!("fingertips.{name}");
                let texts = keyed_numbers(val, &field, &POINT_KEYS)?;
                let mut p = [0f32; 3];
                for k in 0..3 {
                    p[k] = position(texts[k], &format!("field `{field}.{}`", POINT_KEYS[k]))?;
                }
                tips.push((name.clone(), Vec3::from_array(p)));
            }
            // An empty object means no fingertips (CSV cannot tell them apart).
            (!tips.is_empty()).then_some(tips)
        }
    };
    let object = get("object").map(|v| pose_from_json(v, "object")).transpose()?;
    Ok(RawFrame { loc, t, wrist, joints, fingertips, object })
}

/// Serialises one frame as the JSON message (f32 values in their shortest exact form).
pub(super) struct MessageSer<'a> {
    pub(super) traj: &'a Trajectory,
    pub(super) frame: &'a Keyframe,
}

pub(super) struct PoseSer<'a>(&'a Pose);
pub(super) struct PointSer<'a>(&'a Vec3);
pub(super) struct NamedSer<'a, T>(&'a [String], &'a [T]);

impl Serialize for MessageSer<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let f = self.frame;
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("t", &f.t)?;
        m.serialize_entry("wrist", &PoseSer(&f.wrist))?;
        m.serialize_entry("joints", &NamedSer(&self.traj.joint_names, &f.joints))?;
        if let Some(p) = f.fingertips.as_deref().filter(|p| !p.is_empty()) {
            let points: Vec<PointSer> = p.iter().map(PointSer).collect();
            m.serialize_entry("fingertips", &NamedSer(&self.traj.fingertip_names, &points))?;
        }
        if let Some(p) = &f.object {
            m.serialize_entry("object", &PoseSer(p))?;
        }
        m.end()
    }
}

impl Serialize for PoseSer<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(7))?;
        for (k, v) in POSE_KEYS.iter().zip(pose_values(self.0)) {
            m.serialize_entry(k, &v)?;
        }
        m.end()
    }
}

impl Serialize for PointSer<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(3))?;
        for (k, v) in POINT_KEYS.iter().zip(self.0.to_array()) {
            m.serialize_entry(k, &v)?;
        }
        m.end()
    }
}

impl<T: Serialize> Serialize for NamedSer<'_, T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0.iter().zip(self.1) {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}
