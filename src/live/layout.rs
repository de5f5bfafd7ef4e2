//! The Foxglove layout of a live view (Foxglove's exported-layout JSON, "Import layout…"): the 3-D
//! scene of the shown envs, the success rate and mean reward, each reward term, and the learner's
//! losses, plotted against the iteration. `assets/foxglove/dextrain.json` is this layout for the
//! lift task's terms; a run with `--live` writes its own (its task's terms) as
//! `runs/NAME/foxglove_layout.json`.

use serde_json::{Value, json};

use super::metrics::{TOPIC_METRICS, column_path};
use crate::record::{TOPIC_SCENE, TOPIC_TF};

/// The layout shipped in `assets/foxglove/`, relative to the repository.
pub const SHIPPED_LAYOUT: &str = "assets/foxglove/dextrain.json";
/// The layout file a live run writes into its directory.
pub const RUN_LAYOUT: &str = crate::run_dir::FOXGLOVE_LAYOUT;

/// Writes `layout` as pretty JSON to `path` (through a temporary file renamed into place).
pub fn write(path: &std::path::Path, layout: &Value) -> anyhow::Result<()> {
    use anyhow::Context;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(layout)?).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot rename {} to {}", tmp.display(), path.display()))
}

/// One plotted series: a metrics column against the iteration.
fn series(column: &str, label: &str) -> Value {
    json!({"value": format!("{TOPIC_METRICS}.{}", column_path(column)), "enabled": true, "timestampMethod": "receiveTime", "label": label})
}

/// A plot of `columns` ([column, label]) against the iteration.
fn plot(title: &str, columns: &[(String, String)]) -> Value {
    json!({
        "title": title,
        "paths": columns.iter().map(|(c, l)| series(c, l)).collect::<Vec<_>>(),
        "xAxisVal": "custom",
        "xAxisPath": {"value": format!("{TOPIC_METRICS}.iteration"), "enabled": true},
        "showLegend": true,
        "legendDisplay": "floating",
        "isSynced": false
    })
}

/// The layout for a task whose reward terms are `terms` and a learner whose loss columns are
/// `losses` (metrics column names, e.g. `loss/value`).
pub fn layout(terms: &[String], losses: &[String]) -> Value {
    use crate::metrics::columns::*;
    let pair = |c: &str, l: &str| (c.to_string(), l.to_string());
    let progress = [pair(EPISODE_SUCCESS_RATE, "success rate"), pair(REWARD_MEAN, "reward / step")];
    let term_series: Vec<(String, String)> = terms.iter().map(|t| (format!("{REWARD_PREFIX}{t}"), t.clone())).collect();
    let loss_series: Vec<(String, String)> = losses.iter().map(|c| (c.clone(), c.clone())).collect();
    json!({
        "configById": {
            "3D!scene": {
                "followTf": "world",
                "scene": {},
                "transforms": {},
                "cameraState": {"distance": 1.2, "perspective": true, "phi": 55, "thetaOffset": 45, "target": [0.3, 0.3, 0.1], "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.01, "far": 100},
                "layers": {"grid": {"layerId": "foxglove.Grid", "visible": true, "size": 4, "divisions": 40}},
                "topics": {TOPIC_SCENE: {"visible": true}, TOPIC_TF: {"visible": false}}
            },
            "Plot!progress": plot("Progress", &progress),
            "Plot!terms": plot("Reward terms (mean per env step)", &term_series),
            "Plot!losses": plot("Learner", &loss_series),
            "RawMessages!metrics": {"topicPath": TOPIC_METRICS, "diffEnabled": false, "expansion": "all"}
        },
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {
            "direction": "row",
            "splitPercentage": 55,
            "first": "3D!scene",
            "second": {
                "direction": "column",
                "splitPercentage": 33,
                "first": "Plot!progress",
                "second": {
                    "direction": "column",
                    "splitPercentage": 50,
                    "first": "Plot!terms",
                    "second": {"direction": "row", "splitPercentage": 50, "first": "Plot!losses", "second": "RawMessages!metrics"}
                }
            }
        }
    })
}
