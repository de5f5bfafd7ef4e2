//! The live view (`--live [ADDR]` of `train`, `eval` and `replay`): a Foxglove WebSocket server,
//! run by Foxglove's own Rust SDK (the `foxglove` crate), that serves the scene of the first few
//! envs while they step and one metrics message per training iteration. Open it in Foxglove with
//! "Open connection → Foxglove WebSocket" at `ws://ADDR`, and import the layout
//! `assets/foxglove/dextrain.json` (or the run's own `runs/NAME/foxglove_layout.json`).
//!
//! Channels (every message JSON, every schema a JSON Schema, the same messages as a recording's,
//! `crate::record`):
//!
//! | topic               | schema                     | content |
//! |---------------------|----------------------------|---------|
//! | `/tf`               | `foxglove.FrameTransforms` | `world` → `envK/world` (the env's place in a grid, [`ENV_SPACING`] apart), `envK/world` → each link, the object, the reference |
//! | `/scene`            | `foxglove.SceneUpdate`     | each shown env's hand links, object, table, reference ghost, contact points and force arrows, ids under `envK/` |
//! | `/dextrain/metrics` | `dextrain.Metrics`         | each iteration's metrics row as nested JSON ([`metrics`]); a client that subscribes mid-run first gets the rows so far (the last [`HISTORY_REPLAY`]) |
//!
//! Cost: nothing is read or built while no client subscribes (one atomic load per env step). With
//! one, training sends the scene at most `--live-hz` times a second of wall time (default
//! [`DEFAULT_SCENE_HZ`]; the steps between are not shown), each time reading the env batch's
//! states, parameters, springs and targets (on a GPU backend: one readback of each); `eval` and
//! `replay` send every step and hold it back to real time (one control step of wall time per step)
//! unless `--live-hz` is given. Log times are the wall clock, so that Foxglove shows the newest
//! scene; a frame's own episode time is not in the scene messages.

pub mod frames;
pub mod layout;
pub mod metrics;

use std::collections::VecDeque;
use std::net::ToSocketAddrs;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, Result, bail};
use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle};
use glam::Vec3;
use serde_json::json;

use crate::env::SimModel;
use crate::record::{FoxgloveFrames, FoxgloveMessages, TOPIC_SCENE, TOPIC_TF};
use crate::task::TaskBatch;
use frames::{EnvFrame, ObjectKey, env_meta, first_env_frames};
pub use frames::{EnvSlices, env_frames};

/// The address `--live` serves on when given without one.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// Scene messages per second of wall time at most (`--live-hz`).
pub const DEFAULT_SCENE_HZ: f64 = 10.0;
/// Distance between two shown envs' places in the view's grid (m).
pub const ENV_SPACING: f32 = 0.6;
/// The most metrics rows replayed to a client that subscribes mid-run (the newest ones): under the
/// SDK's per-client backlog of 1024 messages, which the replay fills at once.
pub const HISTORY_REPLAY: usize = 900;
/// How long `--live-wait` waits for a client before it goes on without one.
pub const WAIT_FOR_CLIENT: Duration = Duration::from_secs(600);

/// The live view's command-line options (flattened into `train`, `eval` and `replay`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct LiveArgs {
    /// Serve a live 3-D view and the metrics to Foxglove (WebSocket) at ADDR (host:port; port 0
    /// picks a free one; default 127.0.0.1:8765). Give it after the positional arguments, or as
    /// --live=ADDR.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_ADDR)]
    pub live: Option<String>,
    /// Envs shown in the live view (the first K of the batch).
    #[arg(long, value_name = "K", default_value_t = 4, requires = "live")]
    pub live_envs: usize,
    /// Scene messages per second at most (wall time); default: 10 for `train`, every step at real
    /// time for `eval` and `replay`.
    #[arg(long, value_name = "HZ", requires = "live")]
    pub live_hz: Option<f64>,
    /// Wait (up to 10 minutes) for a Foxglove client to subscribe before the first step.
    #[arg(long, requires = "live")]
    pub live_wait: bool,
}

impl LiveArgs {
    /// The live view these options ask for (None without `--live`), its server started, with a
    /// metrics channel for a run whose metrics columns are `metrics_columns`; with `--live-wait`,
    /// once a client watches. `real_time`: without `--live-hz`, send every step at real time
    /// (eval, replay) instead of [`DEFAULT_SCENE_HZ`] scenes a second (training).
    pub fn start(&self, model: &SimModel, control_dt: f32, metrics_columns: Option<&[String]>, real_time: bool) -> Result<Option<LiveView>> {
        let Some(addr) = &self.live else { return Ok(None) };
        if self.live_envs == 0 {
            bail!("--live-envs 0: expected at least 1 env to show");
        }
        let pacing = match self.live_hz {
            Some(hz) if !(hz.is_finite() && hz > 0.0) => bail!("--live-hz {hz}: expected a rate > 0 (scene messages per second)"),
            Some(hz) => Pacing::Throttled { hz },
            None if real_time => Pacing::RealTime { step_s: control_dt as f64 },
            None => Pacing::Throttled { hz: DEFAULT_SCENE_HZ },
        };
        let mut view = LiveView::start(addr, model.clone(), control_dt, self.live_envs, pacing)?;
        if let Some(columns) = metrics_columns {
            view.add_metrics_channel(columns)?;
        }
        if self.live_wait {
            view.wait_for_client(WAIT_FOR_CLIENT);
        }
        Ok(Some(view))
    }
}

/// When a live view sends the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pacing {
    /// At most `hz` scenes a second of wall time; the steps between are not shown (training).
    Throttled { hz: f64 },
    /// Every step, each held back until `step_s` of wall time after the last (eval, replay: real
    /// time).
    RealTime { step_s: f64 },
}

/// What the live view did (the run's summary reports it).
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct LiveStats {
    /// Scene (and transform) messages sent.
    pub scene_messages: u64,
    /// Metrics messages sent.
    pub metrics_messages: u64,
    /// Wall time spent reading envs and building and sending messages (s).
    pub busy_s: f64,
}

/// The metrics channel and the rows sent on it so far (JSON, in order), replayed to a client when it
/// subscribes: a client that connects mid-run gets the run's curves from the first iteration. One
/// lock covers both, so a row goes out either live or in a replay (a row sent between the
/// client's subscription and its replay comes twice, once each way).
#[derive(Default)]
struct MetricsHistory {
    /// The channel, and the newest [`HISTORY_REPLAY`] rows (older ones are dropped).
    inner: Mutex<(Option<Arc<RawChannel>>, VecDeque<Vec<u8>>)>,
}

impl MetricsHistory {
    fn lock(&self) -> MutexGuard<'_, (Option<Arc<RawChannel>>, VecDeque<Vec<u8>>)> {
        // (a panic elsewhere while holding it leaves the rows as they were: still usable)
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl ServerListener for MetricsHistory {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        let g = self.lock();
        let (Some(ch), rows) = (&g.0, &g.1) else { return };
        if channel.id() == ch.id() {
            for row in rows {
                ch.log_to_sink(row, client.sink_id());
            }
        }
    }
}

/// A running live view (see the module docs). Dropping it stops the server.
pub struct LiveView {
    /// The server's own runtime: one worker thread (the SDK's default takes one per core).
    runtime: Option<tokio::runtime::Runtime>,
    server: Option<WebSocketServerHandle>,
    /// The channels' context (kept alive: dropping it closes the channels).
    _context: Arc<Context>,
    tf: Arc<RawChannel>,
    scene: Arc<RawChannel>,
    /// The metrics channel (once [`LiveView::add_metrics_channel`] made it) and its rows so far.
    metrics: Arc<MetricsHistory>,
    /// The address clients connect to (`ws://host:port`).
    url: String,
    model: SimModel,
    control_dt: f32,
    envs: usize,
    pacing: Pacing,
    last_scene: Option<Instant>,
    /// Each shown env's message builder and the object it was built for.
    builders: Vec<Option<(ObjectKey, FoxgloveFrames)>>,
    stats: LiveStats,
}

impl LiveView {
    /// Starts the server at `addr` (`host:port`) for the first `envs` envs of batches of `model`.
    pub fn start(addr: &str, model: SimModel, control_dt: f32, envs: usize, pacing: Pacing) -> Result<LiveView> {
        let (host, port) = parse_addr(addr)?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("dextrain-live")
            .enable_all()
            .build()
            .context("--live: cannot start the live view's runtime")?;
        let context = Context::new();
        let json_channel = |topic: &str, schema_name: &str, schema: serde_json::Value| -> Result<Arc<RawChannel>> {
            Ok(context
                .channel_builder(topic)
                .message_encoding("json")
                .schema(Schema::new(schema_name, "jsonschema", serde_json::to_vec(&schema)?))
                .build_raw()?)
        };
        let tf = json_channel(TOPIC_TF, crate::record::SCHEMA_FRAME_TRANSFORMS, crate::record::frame_transforms_json_schema())?;
        let scene = json_channel(TOPIC_SCENE, crate::record::SCHEMA_SCENE_UPDATE, crate::record::scene_update_json_schema())?;
        let metrics = Arc::new(MetricsHistory::default());
        let server = WebSocketServer::new()
            .name(format!("dextrain {}", env!("CARGO_PKG_VERSION")))
            .bind(host.clone(), port)
            .context(&context)
            .listener(metrics.clone())
            .tokio_runtime(runtime.handle())
            .start_blocking()
            .with_context(|| format!("--live {addr}: cannot serve the live view there (a port in use, or an address not of this machine?)"))?;
        let url = format!("ws://{host}:{}", server.port());
        crate::console::status(&format!("dextrain: live view at {url} (Foxglove: Open connection → Foxglove WebSocket; layout {})", layout::SHIPPED_LAYOUT));
        Ok(LiveView {
            runtime: Some(runtime),
            server: Some(server),
            _context: context,
            tf,
            scene,
            metrics,
            url,
            model,
            control_dt,
            envs,
            pacing,
            last_scene: None,
            builders: vec![None; envs],
            stats: LiveStats::default(),
        })
    }

    /// `ws://host:port` of the server.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// What the view did so far.
    pub fn stats(&self) -> LiveStats {
        self.stats
    }

    /// Waits until a client subscribes to a channel, or `timeout` passes.
    pub fn wait_for_client(&self, timeout: Duration) {
        crate::console::status(&format!("dextrain: waiting for a Foxglove client at {} (--live-wait)", self.url));
        let t0 = Instant::now();
        while !self.anyone_watching() && t0.elapsed() < timeout {
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn anyone_watching(&self) -> bool {
        self.tf.has_sinks() || self.scene.has_sinks() || self.metrics.lock().0.as_ref().is_some_and(|m| m.has_sinks())
    }

    /// True when a client subscribed to the scene and, throttled, the last scene went out at least a
    /// period ago: the caller then reads the shown envs and calls [`LiveView::send_scene`].
    pub fn wants_scene(&self) -> bool {
        if !(self.scene.has_sinks() || self.tf.has_sinks()) {
            return false;
        }
        match (self.pacing, self.last_scene) {
            (Pacing::Throttled { hz }, Some(t)) => t.elapsed().as_secs_f64() >= 1.0 / hz,
            _ => true,
        }
    }

    /// Sends the shown envs of `task` when [`LiveView::wants_scene`]. Call once per env step.
    pub fn after_step(&mut self, task: &mut dyn TaskBatch) -> Result<()> {
        if !self.wants_scene() {
            return Ok(());
        }
        let t0 = Instant::now();
        let frames = first_env_frames(&self.model, task, self.envs)?;
        self.stats.busy_s += t0.elapsed().as_secs_f64();
        self.send_scene(&frames)
    }

    /// The number of envs shown (`--live-envs`).
    pub fn shown_envs(&self) -> usize {
        self.envs
    }

    /// Sends `frames` (env k's at k) as one transforms message and one scene message; at real
    /// time, first waits until a step of wall time has passed since the last.
    pub fn send_scene(&mut self, frames: &[EnvFrame]) -> Result<()> {
        if let (Pacing::RealTime { step_s }, Some(last)) = (self.pacing, self.last_scene) {
            let due = Duration::from_secs_f64(step_s);
            if let Some(rest) = due.checked_sub(last.elapsed()) {
                std::thread::sleep(rest);
            }
        }
        let t0 = Instant::now();
        self.last_scene = Some(t0);
        let stamp = now_ns();
        let columns = (frames.len() as f32).sqrt().ceil().max(1.0) as usize;
        let mut out = FoxgloveMessages::default();
        for (k, f) in frames.iter().enumerate() {
            // an env's object may change at its reset: its builder then too
            if !matches!(&self.builders[k], Some((key, _)) if *key == f.object) {
                self.builders[k] = Some((f.object, FoxgloveFrames::new(&env_meta(&self.model, f.object, self.control_dt), &format!("env{k}/"))));
            }
            // a grid, row by row along +x, rows along +y
            let place = Vec3::new((k % columns) as f32, (k / columns) as f32, 0.0) * ENV_SPACING;
            if let Some((_, builder)) = &self.builders[k] {
                builder.append(&f.frame, stamp, Some(place), &mut out);
            }
        }
        self.tf.log(&out.tf_json()?);
        self.scene.log(&out.scene_json()?);
        self.stats.scene_messages += 1;
        self.stats.busy_s += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Declares the metrics channel for a run whose metrics columns are `columns` (once, before
    /// the first [`LiveView::metrics`]).
    pub fn add_metrics_channel(&mut self, columns: &[String]) -> Result<()> {
        let schema = metrics::metrics_schema(columns);
        let channel = self
            ._context
            .channel_builder(metrics::TOPIC_METRICS)
            .message_encoding("json")
            .schema(Schema::new(metrics::SCHEMA_METRICS, "jsonschema", serde_json::to_vec(&schema)?))
            .build_raw()?;
        self.metrics.lock().0 = Some(channel);
        Ok(())
    }

    /// Sends iteration `iteration`'s metrics `row` (in the channel's `columns` order) to the
    /// clients that subscribed to it, and keeps it for those that subscribe later.
    pub fn metrics(&mut self, iteration: u64, columns: &[String], row: &[f64]) -> Result<()> {
        let t0 = Instant::now();
        let bytes = serde_json::to_vec(&metrics::metrics_message(iteration, columns, row))?;
        let mut g = self.metrics.lock();
        let Some(ch) = g.0.clone() else { return Ok(()) };
        if ch.has_sinks() {
            ch.log(&bytes);
            self.stats.metrics_messages += 1;
        }
        g.1.push_back(bytes);
        if g.1.len() > HISTORY_REPLAY {
            g.1.pop_front();
        }
        drop(g);
        self.stats.busy_s += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// The stats as JSON, for a command's summary.
    pub fn summary(&self) -> serde_json::Value {
        json!({"url": self.url, "scene_messages": self.stats.scene_messages, "metrics_messages": self.stats.metrics_messages, "busy_s": self.stats.busy_s})
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            server.stop().wait_blocking();
        }
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_timeout(Duration::from_secs(1));
        }
    }
}

/// Nanoseconds since the Unix epoch, now.
fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// `host:port` of `--live`, checked: a port number and a host this machine resolves.
fn parse_addr(addr: &str) -> Result<(String, u16)> {
    let bad = |why: &str| anyhow::anyhow!("--live {addr:?}: {why}; expected HOST:PORT such as {DEFAULT_ADDR} (port 0: any free port); give --live after the positional arguments or as --live=ADDR");
    let (host, port) = addr.rsplit_once(':').ok_or_else(|| bad("no port"))?;
    let port: u16 = port.parse().map_err(|_| bad("the port is not a number from 0 to 65535"))?;
    // (an IPv6 host keeps its brackets: the server binds "HOST:PORT")
    let bare = host.trim_start_matches('[').trim_end_matches(']');
    if bare.is_empty() {
        return Err(bad("no host"));
    }
    (bare, port).to_socket_addrs().map_err(|e| bad(&format!("the host does not resolve ({e})")))?;
    Ok((host.to_string(), port))
}
