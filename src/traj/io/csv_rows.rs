//! The CSV side of the reference format: the column layout, rows from and to frames.

use super::*;

#[derive(Clone, Copy)]
pub(super) enum Col {
    T,
    Wrist(usize),
    Joint(usize),
    Tip(usize, usize),
    Object(usize),
}

pub(super) struct CsvLayout {
    pub(super) names: Vec<String>,
    pub(super) cols: Vec<Col>,
    pub(super) joint_names: Vec<String>,
    pub(super) tip_names: Vec<String>,
    pub(super) has_object: bool,
}

pub(super) const CSV_COLUMNS_HINT: &str = "t, wrist_x … wrist_qw, joint:<name>, tip:<name>:x|y|z or object_x … object_qw";

impl CsvLayout {
    pub(super) fn parse(header: &str) -> Result<CsvLayout, String> {
        let names: Vec<String> = header.split(',').map(|c| c.trim().to_string()).collect();
        let mut cols = Vec::with_capacity(names.len());
        let mut joint_names: Vec<String> = Vec::new();
        let mut tip_names: Vec<String> = Vec::new();
        let mut seen = BTreeSet::new();
        let bad_name = |c: &str, n: &str| {
            format!(
                "column {c:?}: name {n:?}: expected a non-empty name without whitespace, control characters, commas or double quotes"
            )
        };
        for (i, c) in names.iter().enumerate() {
            if c.is_empty() {
                return Err(format!("column {}: empty column name: expected one of {CSV_COLUMNS_HINT}", i + 1));
            }
            if !seen.insert(c.as_str()) {
                return Err(format!("column {c:?}: duplicate column: expected each column once"));
            }
            let pose_key = |prefix: &str| c.strip_prefix(prefix).and_then(|k| POSE_KEYS.iter().position(|&p| p == k));
            let col = if c == "t" {
                Col::T
            } else if let Some(k) = pose_key("wrist_") {
                Col::Wrist(k)
            } else if let Some(k) = pose_key("object_") {
                Col::Object(k)
            } else if let Some(name) = c.strip_prefix("joint:") {
                if !is_valid_name(name) {
                    return Err(bad_name(c, name));
                }
                joint_names.push(name.to_string());
                Col::Joint(joint_names.len() - 1)
            } else if let Some((name, axis)) = c.strip_prefix("tip:").and_then(|r| r.rsplit_once(':')) {
                let Some(a) = POINT_KEYS.iter().position(|&p| p == axis) else {
                    return Err(format!("column {c:?}: unknown fingertip axis {axis:?}: expected x, y or z"));
                };
                if !is_valid_name(name) {
                    return Err(bad_name(c, name));
                }
                let k = match tip_names.iter().position(|n| n == name) {
                    Some(k) => k,
                    None => {
                        tip_names.push(name.to_string());
                        tip_names.len() - 1
                    }
                };
                Col::Tip(k, a)
            } else {
                return Err(format!("unknown column {c:?}: expected one of {CSV_COLUMNS_HINT}"));
            };
            cols.push(col);
        }
        let has = |name: &str| names.iter().any(|n| n == name);
        if !has("t") {
            return Err("missing column `t`: expected the time (s) in a column named t".into());
        }
        for k in POSE_KEYS {
            if !has(&format!("wrist_{k}")) {
                return Err(format!(
                    "missing column `wrist_{k}`: expected all of wrist_x, wrist_y, wrist_z, wrist_qx, wrist_qy, wrist_qz, wrist_qw"
                ));
            }
        }
        let has_object = POSE_KEYS.iter().any(|k| has(&format!("object_{k}")));
        if has_object {
            for k in POSE_KEYS {
                if !has(&format!("object_{k}")) {
                    return Err(format!(
                        "missing column `object_{k}`: expected all 7 object columns (object_x … object_qw) or none"
                    ));
                }
            }
        }
        for name in &tip_names {
            for a in POINT_KEYS {
                if !has(&format!("tip:{name}:{a}")) {
                    return Err(format!("missing column `tip:{name}:{a}`: expected tip:{name}:x, :y and :z"));
                }
            }
        }
        Ok(CsvLayout { names, cols, joint_names, tip_names, has_object })
    }

    pub(super) fn row(&self, line: &str, loc: Loc) -> Result<RawFrame, String> {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != self.cols.len() {
            return Err(format!("expected {} columns as in the header, got {}", self.cols.len(), cells.len()));
        }
        let mut t = 0.0;
        let mut wrist = [""; 7];
        let mut object = [""; 7];
        let mut joints: Vec<(String, f32)> = self.joint_names.iter().map(|n| (n.clone(), 0.0)).collect();
        let mut tips: Vec<(String, Vec3)> = self.tip_names.iter().map(|n| (n.clone(), Vec3::ZERO)).collect();
        for ((col, name), &cell) in self.cols.iter().zip(&self.names).zip(&cells) {
            let label = || format!("column `{name}`");
            match *col {
                Col::T => t = time(cell, &label())?,
                Col::Wrist(k) => wrist[k] = cell,
                Col::Object(k) => object[k] = cell,
                Col::Joint(j) => joints[j].1 = joint_value(cell, &label())?,
                Col::Tip(j, a) => tips[j].1[a] = position(cell, &label())?,
            }
        }
        let labels = |prefix: &str| POSE_KEYS.map(|k| format!("column `{prefix}_{k}`"));
        let quat = |prefix: &str| format!("columns `{prefix}_qx`, `{prefix}_qy`, `{prefix}_qz`, `{prefix}_qw`");
        let wrist = pose_from_texts(wrist, &labels("wrist"), &quat("wrist"))?;
        let object =
            if self.has_object { Some(pose_from_texts(object, &labels("object"), &quat("object"))?) } else { None };
        let fingertips = (!tips.is_empty()).then_some(tips);
        Ok(RawFrame { loc, t, wrist, joints, fingertips, object })
    }
}
