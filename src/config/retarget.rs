//! `[retarget]`: how `dextrain traj retarget` maps a human hand onto the config's hand.

use serde::{Deserialize, Serialize};

/// `traj retarget`'s settings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetargetConfig {
    /// The robot fingertip (a name of the hand's fingertips) each human finger drives, in place of
    /// the automatic map (src/retarget/keypoint_map.rs); a finger left out is not mapped. Unset:
    /// the automatic map.
    pub fingers: Option<FingerMap>,
}

/// Human finger → robot fingertip name (`[retarget.fingers]`): the thumb and at least one other.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerMap {
    /// The fingertip the human thumb drives (required).
    pub thumb: String,
    /// The fingertip the human index finger drives.
    pub index: Option<String>,
    /// The fingertip the human middle finger drives.
    pub middle: Option<String>,
    /// The fingertip the human ring finger drives.
    pub ring: Option<String>,
    /// The fingertip the human little finger drives.
    pub little: Option<String>,
}

impl FingerMap {
    /// The mapped fingers: (human finger, thumb first as 0 … little as 4; its key; the fingertip).
    pub fn entries(&self) -> Vec<(usize, &'static str, &str)> {
        let named = [("thumb", Some(&self.thumb)), ("index", self.index.as_ref()), ("middle", self.middle.as_ref()), ("ring", self.ring.as_ref()), ("little", self.little.as_ref())];
        named.into_iter().enumerate().filter_map(|(i, (key, tip))| tip.map(|t| (i, key, t.as_str()))).collect()
    }
}
