//! The live view's metrics message: one per training iteration, the run's `metrics.csv` row as
//! nested JSON (a column `a/b` is `{"a": {"b": …}}`, so that Foxglove's message paths reach it as
//! `/dextrain/metrics.a.b`: `reward.mean`, `reward.<term>`, `episode.success_rate`, `loss.value`,
//! `kl`…), with `iteration` beside them. A value that is not finite (no episode ended yet) is null.

use serde_json::{Map, Value, json};

/// Topic of the metrics messages.
pub const TOPIC_METRICS: &str = "/dextrain/metrics";
/// Their schema's name.
pub const SCHEMA_METRICS: &str = "dextrain.Metrics";

/// The message path of a metrics column below the topic: `reward/mean` → `reward.mean`.
pub fn column_path(column: &str) -> String {
    column.replace('/', ".")
}

/// The JSON message of iteration `iteration` whose values are `row`, one per `columns` entry.
pub fn metrics_message(iteration: u64, columns: &[String], row: &[f64]) -> Value {
    let mut root = Map::new();
    root.insert("iteration".to_string(), json!(iteration));
    for (c, &v) in columns.iter().zip(row) {
        let value = if v.is_finite() { json!(v) } else { Value::Null };
        insert_path(&mut root, c, value);
    }
    Value::Object(root)
}

/// The JSON Schema of the messages of a run whose columns are `columns` (every column a number or
/// null, at its nested place).
pub fn metrics_schema(columns: &[String]) -> Value {
    let mut root = Map::new();
    root.insert("iteration".to_string(), json!({"type": "integer", "description": "The training iteration this row ends (1 = the first)."}));
    for c in columns {
        insert_path(&mut root, c, json!({"type": ["number", "null"], "description": format!("metrics.csv column `{c}`")}));
    }
    let mut schema = as_schema(Value::Object(root));
    schema["title"] = json!(SCHEMA_METRICS);
    schema["description"] = json!("One row of a dextrain run's metrics.csv, per training iteration");
    schema
}

/// Sets `value` at `path`'s place in `root` (`a/b/c`: root.a.b.c). Where a name on the way is
/// already a value (a column `a` and another `a/b`), the longer column goes flat into `root`,
/// under its whole path with dots.
fn insert_path(root: &mut Map<String, Value>, path: &str, value: Value) {
    let parts: Vec<&str> = path.split('/').collect();
    let (inner, leaf) = parts.split_at(parts.len() - 1);
    // the objects on the way exist or can be made
    let mut probe: &Map<String, Value> = root;
    for p in inner {
        match probe.get(*p) {
            Some(Value::Object(m)) => probe = m,
            Some(_) => {
                root.insert(column_path(path), value);
                return;
            }
            None => break,
        }
    }
    let mut node = root;
    for p in inner {
        let Value::Object(m) = node.entry(p.to_string()).or_insert_with(|| Value::Object(Map::new())) else { return };
        node = m;
    }
    node.insert(leaf[0].to_string(), value);
}

/// A nested map of leaf schemas as a JSON Schema: every inner map becomes an object schema.
fn as_schema(v: Value) -> Value {
    match v {
        Value::Object(m) if !m.contains_key("type") => {
            let properties: Map<String, Value> = m.into_iter().map(|(k, v)| (k, as_schema(v))).collect();
            json!({"type": "object", "properties": properties})
        }
        leaf => leaf,
    }
}
