//! The starter config's text: configs/lift_cube_cpu.toml's run, task, learner and network sections
//! (the lift task sized for a 2-core CPU) around the `[hand]`, `[wrist]`, `[object]` and
//! `[task.hand]` sections that `dextrain new` fills in, each key under the comment that says where
//! its value came from.
//!
//! Keep the fixed sections in step with configs/lift_cube_cpu.toml (tests/suite/starter.rs
//! compares the loaded configs).

use std::fmt::Write as _;

/// One `key = value` line with the comment lines written above it.
#[derive(Clone, Debug)]
pub struct Entry {
    /// Comment lines above the key (without the `# `).
    pub comment: Vec<String>,
    /// The key (a bare TOML key).
    pub key: String,
    /// The value, written inline.
    pub value: toml::Value,
}

/// A `[table]`: comment lines under its header, then its entries.
#[derive(Clone, Debug)]
pub struct Section {
    /// The table's dotted name (`hand`, `task.hand`).
    pub name: String,
    /// Comment lines under the header (without the `# `).
    pub comment: Vec<String>,
    /// The keys, in the order written.
    pub entries: Vec<Entry>,
}

impl Section {
    /// An empty `[name]`.
    pub fn new(name: &str) -> Section {
        Section { name: name.to_string(), comment: Vec::new(), entries: Vec::new() }
    }

    /// Adds `key = value` under the comment lines `comment` (none for an empty slice).
    pub fn push(&mut self, comment: &[String], key: &str, value: toml::Value) {
        self.entries.push(Entry { comment: comment.to_vec(), key: key.to_string(), value });
    }

    /// The value of `key`, if the section has it.
    pub fn get(&self, key: &str) -> Option<&toml::Value> {
        self.entries.iter().find(|e| e.key == key).map(|e| &e.value)
    }

    /// The section as TOML text (header, comments, one line per key), ending in a newline.
    pub fn render(&self) -> String {
        let mut out = format!("[{}]\n", self.name);
        for c in &self.comment {
            push_comment(&mut out, c);
        }
        for e in &self.entries {
            for c in &e.comment {
                push_comment(&mut out, c);
            }
            let line = format!("{} = {}", e.key, e.value);
            match &e.value {
                // a long array one element a line (an inline table stays on one line, as TOML 1.0 wants)
                toml::Value::Array(items) if line.chars().count() > LINE_CHARS => {
                    let _ = writeln!(out, "{} = [", e.key);
                    for item in items {
                        let _ = writeln!(out, "    {item},");
                    }
                    out.push_str("]\n");
                }
                _ => {
                    let _ = writeln!(out, "{line}");
                }
            }
        }
        out
    }
}

/// Longest comment line (characters) before it wraps, and longest `key = [...]` line before the
/// array is written one element a line.
pub const LINE_CHARS: usize = 100;

/// `# text`, wrapped at word boundaries to [`LINE_CHARS`].
fn push_comment(out: &mut String, text: &str) {
    let mut line = String::from("#");
    for word in text.split(' ') {
        if line.chars().count() + 1 + word.chars().count() > LINE_CHARS && line != "#" {
            let _ = writeln!(out, "{}", line.trim_end());
            line = String::from("#");
        }
        line.push(' ');
        line.push_str(word);
    }
    let _ = writeln!(out, "{}", line.trim_end());
}

/// A number for the TOML, rounded to `decimals` decimal places (so that 1.5707963 is written as
/// such and not as the f32's 1.5707963705062866).
pub fn num(x: f32, decimals: i32) -> toml::Value {
    let scale = 10f64.powi(decimals);
    let v = (x as f64 * scale).round() / scale;
    // −0.0 reads oddly in a config
    toml::Value::Float(if v == 0.0 { 0.0 } else { v })
}

/// Three numbers, each rounded to `decimals` decimal places.
pub fn vec3(v: [f32; 3], decimals: i32) -> toml::Value {
    toml::Value::Array(v.iter().map(|x| num(*x, decimals)).collect())
}

/// A string value (quoted and escaped as TOML wants).
pub fn string(s: &str) -> toml::Value {
    toml::Value::String(s.to_string())
}

/// The parts of the starter that `dextrain new` guesses; the rest is configs/lift_cube_cpu.toml.
#[derive(Clone, Debug)]
pub struct Starter {
    /// The comment lines at the top of the file (without the `# `).
    pub title: Vec<String>,
    /// `[hand]`.
    pub hand: Section,
    /// `[wrist]`.
    pub wrist: Section,
    /// `[object]`.
    pub object: Section,
    /// `[task.hand]`.
    pub task_hand: Section,
    /// The top of the box the wrist's position target is clipped to (m): configs/lift_cube_cpu.toml's
    /// 0.35, or more for a hand that starts higher.
    pub wrist_pos_max_z: f32,
}

/// The `[object]` of configs/lift_cube_cpu.toml: the 5 cm, 0.1 kg cube with the issue's
/// randomisation (±5 cm in x and y, ±30° about z).
pub fn cube_object() -> Section {
    let mut s = Section::new("object");
    let mut shape = toml::Table::new();
    shape.insert("type".into(), string("box"));
    shape.insert("half_extents".into(), vec3([0.025; 3], 4));
    s.push(&["the 5 cm, 0.1 kg cube of configs/lift_cube_cpu.toml".to_string()], "shape", toml::Value::Table(shape));
    s.push(&[], "mass", num(0.1, 4));
    push_object_common(&mut s);
    s
}

/// The keys every starter's `[object]` shares with configs/lift_cube_cpu.toml: friction and the
/// issue's randomisation of the object's place (±5 cm in x and y, ±30° about z).
pub fn push_object_common(s: &mut Section) {
    s.push(&[], "friction", num(1.0, 4));
    s.push(&["the issue's randomisation: ±5 cm in x and y, ±30° about z".to_string()], "xy_noise", toml::Value::Array(vec![num(0.05, 4), num(0.05, 4)]));
    s.push(&[], "yaw_noise", num(0.5235988, 7));
}

/// The whole config file.
pub fn render(s: &Starter) -> String {
    let mut out = String::new();
    for line in &s.title {
        push_comment(&mut out, line);
    }
    out.push_str(
        "seed = 0

[sim]
backend = \"auto\"             # a hardware GPU when wgpu finds one, else the CPU (this config is sized for the CPU)
num_envs = 256

",
    );
    out.push_str(&s.hand.render());
    out.push('\n');
    out.push_str(&s.wrist.render());
    out.push('\n');
    out.push_str(&s.object.render());
    let _ = write!(
        out,
        "
[task]
kind = \"lift\"
episode_length = 90          # 3 s at 30 Hz

[task.action]
finger_mode = \"absolute\"
wrist_pos_scale = 0.01       # m per env step at |a| = 1
wrist_rot_scale = 0.05       # rad per env step at |a| = 1
wrist_pos_min = [-0.2, -0.2, 0.03]
wrist_pos_max = [0.2, 0.2, {}]
wrist_rot_limit = 0.8

[task.rewards]
reaching = 1.0
lifting = 0.5
contact = 0.5
success = 5.0
action_rate = -0.0005
action_magnitude = -0.001

[task.lift]
reach_alpha = 10.0
success_height = 0.10

",
        num(s.wrist_pos_max_z, 2)
    );
    out.push_str(&s.task_hand.render());
    out.push_str(
        "
[train]
device = \"auto\"              # the learner follows the simulator: burn wgpu on its GPU, else burn flex on the CPU
iterations = 1500
steps_per_env = 24
save_interval = 100
plot_interval = 100

[ppo]
learning_rate = 5e-4
schedule = \"adaptive\"
desired_kl = 0.01
gamma = 0.99
lam = 0.95
clip_param = 0.2
value_loss_coef = 1.0
entropy_coef = 0.005
epochs = 5
minibatches = 4
max_grad_norm = 1.0

[policy]
actor_hidden = [256, 128, 64]
critic_hidden = [256, 128, 64]
activation = \"elu\"
init_std = 1.0
obs_normalization = true
",
    );
    out
}
