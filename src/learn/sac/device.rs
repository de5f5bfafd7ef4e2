//! SAC's device-resident loop (docs/gpu.md "The GPU loop"): with the envs and burn's wgpu learner on one
//! wgpu device, the replay buffer lives in device memory and the env loop's observations, actions
//! and rewards never cross to the host:
//! - [`DeviceReplay`]: buffer.rs's rings as `[C·N, dim]` tensors of burn's; a push is one
//!   `copy_buffer_to_buffer` per array from the step's tensors into slot `pos` (`gpu::io`);
//!   a sample reads the rows that the host buffer's [`ReplayBuffer::draw`] picks (the host RNG, as
//!   the host path) and computes the n-step windows with gathers and masks;
//! - the normalisers (`normalizer::DeviceNormalizers`), the random actions and the action noise
//!   (`learn::noise::DeviceNoise`: the host path's draws) on the device.
//!
//! What crosses per env step: 16 bytes of noise parameters; per gradient step: the batch's rows
//! (`8 · n_step · B` bytes: row indices and window flags), another 32 bytes of noise parameters
//! and the step's four loss scalars read back (as on the host path). The buffer comes to the host
//! when a checkpoint holds it.

use anyhow::{Context, Result, ensure};
use burn::prelude::*;
use burn::tensor::{Int, TensorData};

use super::buffer::{Draw, ReplayBuffer};
use super::{GradBatch, Sac};
use crate::gpu::context::{BufferRole, GpuContext};
use crate::gpu::io::{TensorBuffer, flush, zeros_buffer};
use crate::learn::nets::{to_host, to_tensor};
use crate::learn::noise::DeviceNoise;
use crate::learn::normalizer::DeviceNormalizers;

/// One array of the device buffer: `[C·N, dim]` (row `slot · N + env`), stored as pieces of
/// `slots_per_piece` whole slots (`[slots_per_piece · N, dim]` each, the last one shorter) so that
/// no piece is larger than one storage binding of the adapter (`sac.device_piece_bytes` lowers it).
struct Ring {
    name: &'static str,
    dim: usize,
    /// Rows of one slot (the envs).
    envs: usize,
    slots_per_piece: usize,
    pieces: Vec<TensorBuffer>,
}

/// A ring as the gather kernel reads it: its pieces in order.
fn ring_view(r: &Ring) -> crate::learn::kernels::replay_sample::RingView<'_> {
    crate::learn::kernels::replay_sample::RingView { pieces: r.pieces.iter().map(|p| &p.tensor).collect(), dim: r.dim }
}

impl Ring {
    /// Rows of one full piece.
    fn rows_per_piece(&self) -> usize {
        self.slots_per_piece * self.envs
    }

    /// The pieces holding the ring's first `rows` rows: (piece, its first row in the ring, how many
    /// of those rows it holds), the pieces past them left out.
    fn written(&self, rows: usize) -> impl Iterator<Item = (&TensorBuffer, usize, usize)> {
        self.pieces.iter().enumerate().filter_map(move |(k, piece)| {
            let start = k * self.rows_per_piece();
            let take = rows.saturating_sub(start).min(piece.tensor.dims()[0]);
            (take > 0).then_some((piece, start, take))
        })
    }

    /// Bytes of device memory.
    fn size(&self) -> u64 {
        self.pieces.iter().map(TensorBuffer::size).sum()
    }

    /// The rows `idx` `[B]` (of the whole ring) → `[B, dim]`: one gather from a single piece; from
    /// several, each piece's gather of the rows it holds (other rows clamped into it and masked
    /// out), added: exact copies either way.
    fn gather(&self, idx: &Tensor<1, Int>) -> Tensor<2> {
        if self.pieces.len() == 1 {
            return self.pieces[0].tensor.clone().select(0, idx.clone());
        }
        let rpp = self.rows_per_piece() as i64;
        let mut out: Option<Tensor<2>> = None;
        for (k, piece) in self.pieces.iter().enumerate() {
            let start = k as i64 * rpp;
            let rows = piece.tensor.dims()[0] as i64;
            let local = idx.clone().sub_scalar(start).clamp(0, rows - 1); // [B], inside the piece
            let inside = idx.clone().greater_equal_elem(start).bool_and(idx.clone().lower_elem(start + rows)); // [B]
            let picked = piece.tensor.clone().select(0, local) * inside.float().unsqueeze_dim::<2>(1); // [B, dim]
            out = Some(match out {
                Some(o) => o + picked,
                None => picked,
            });
        }
        out.expect("a ring has a piece")
    }
}

/// The replay buffer's arrays on the device; the slot counters stay in the host [`ReplayBuffer`].
pub struct DeviceReplay {
    ctx: GpuContext,
    device: Device,
    envs: usize,
    /// Actor observations before / after (absent when `sac.store_actor_obs` is off).
    obs: Option<Ring>,
    next_obs: Option<Ring>,
    priv_obs: Ring,
    next_priv_obs: Ring,
    actions: Ring,
    /// The learner's rewards, done (termination or time-out) and terminated flags `[C·N, 1]`.
    rewards: Ring,
    done: Ring,
    terminated: Ring,
    /// One push's data on its way (wgpu copies no buffer into itself, and burn's tensors may share
    /// one): every array's `[N, dim]` back to back.
    scratch: wgpu::Buffer,
}

/// What a gradient step takes from the device buffer ([`DeviceReplay::sample_batch`]): the actor's
/// and the critic's observations of each window's first transition and after its last
/// (`[B, O]`, `[B, P]`, normalised when asked), the actions `[B, A]`, the n-step return and the
/// bootstrap factor `[B, 1]`; tensors of burn's wgpu device without autodiff.
pub struct SampledBatch {
    pub obs: Tensor<2>,
    pub next_obs: Tensor<2>,
    pub priv_obs: Tensor<2>,
    pub next_priv: Tensor<2>,
    pub actions: Tensor<2>,
    pub returns: Tensor<2>,
    pub bootstrap: Tensor<2>,
}

/// One push: every env's transition, `[N, dim]` tensors (flags 0 or 1, `[N, 1]`).
pub struct DeviceTransitions<'a> {
    pub obs: Option<&'a Tensor<2>>,
    pub priv_obs: &'a Tensor<2>,
    pub actions: &'a Tensor<2>,
    pub rewards: &'a Tensor<2>,
    pub done: &'a Tensor<2>,
    pub terminated: &'a Tensor<2>,
    pub next_obs: Option<&'a Tensor<2>>,
    pub next_priv_obs: &'a Tensor<2>,
}

impl DeviceReplay {
    /// Zeroed rings shaped as `host`'s (its sizes; its data is not copied), on `device` (burn's wgpu
    /// runtime on `ctx`'s device), each in pieces of at most `piece_bytes` (0: the adapter's
    /// largest storage binding). A slot's rows larger than a piece is a one-line error.
    pub fn new(ctx: &GpuContext, device: &Device, host: &ReplayBuffer, piece_bytes: u64) -> Result<DeviceReplay> {
        let l = ctx.device.limits();
        let binding = (l.max_storage_buffer_binding_size as u64).min(l.max_buffer_size);
        let limit = if piece_bytes > 0 { piece_bytes.min(binding) } else { binding };
        let (envs, capacity) = (host.envs, host.capacity);
        let ring = |name: &'static str, dim: usize| -> Result<Ring> {
            let slot_bytes = (4 * envs * dim.max(1)) as u64;
            let slots_per_piece = ((limit / slot_bytes) as usize).min(capacity);
            if slots_per_piece == 0 {
                // one slot (every env's transition of a step) does not fit one binding: the error names the limit
                ctx.check_buffer_size(name, slot_bytes, BufferRole::Storage)
                    .and_then(|_| Err(anyhow::anyhow!("GPU buffer `{name}`: one slot needs {slot_bytes} bytes, over `sac.device_piece_bytes` = {piece_bytes}")))
                    .with_context(|| format!("key `sim.num_envs` = {envs}: the replay buffer's `{name}` on the device"))?;
            }
            let pieces = (0..capacity.div_ceil(slots_per_piece))
                .map(|k| zeros_buffer(slots_per_piece.min(capacity - k * slots_per_piece) * envs, dim, device))
                .collect::<Result<Vec<_>>>()?;
            Ok(Ring { name, dim, envs, slots_per_piece, pieces })
        };
        let od = host.obs_dim;
        let per_env = 2 * od + 2 * host.priv_dim + host.act_dim + 3;
        let scratch = ctx.create_buffer_with("replay push", &vec![0u8; 4 * host.envs * per_env], BufferRole::Storage, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST)?;
        Ok(DeviceReplay {
            scratch,
            obs: if od > 0 { Some(ring("obs", od)?) } else { None },
            next_obs: if od > 0 { Some(ring("next_obs", od)?) } else { None },
            priv_obs: ring("priv_obs", host.priv_dim)?,
            next_priv_obs: ring("next_priv_obs", host.priv_dim)?,
            actions: ring("actions", host.act_dim)?,
            rewards: ring("rewards", 1)?,
            done: ring("done", 1)?,
            terminated: ring("terminated", 1)?,
            ctx: ctx.clone(),
            device: device.clone(),
            envs: host.envs,
        })
    }

    fn rings(&self) -> Vec<&Ring> {
        let mut r: Vec<&Ring> = self.obs.iter().chain(self.next_obs.iter()).collect();
        r.extend([&self.priv_obs, &self.next_priv_obs, &self.actions, &self.rewards, &self.done, &self.terminated]);
        r
    }

    /// Writes every env's transition into slot `slot` (the host buffer's `pos`; the caller then
    /// advances it): one copy per array, on the device.
    pub fn push(&self, slot: usize, t: &DeviceTransitions<'_>) -> Result<()> {
        use crate::gpu::io::tensor_buffer;
        let n = self.envs;
        let mut pairs: Vec<(&Ring, &Tensor<2>)> = vec![
            (&self.priv_obs, t.priv_obs),
            (&self.next_priv_obs, t.next_priv_obs),
            (&self.actions, t.actions),
            (&self.rewards, t.rewards),
            (&self.done, t.done),
            (&self.terminated, t.terminated),
        ];
        match (&self.obs, t.obs, &self.next_obs, t.next_obs) {
            (Some(o), Some(x), Some(no), Some(nx)) => pairs.extend([(o, x), (no, nx)]),
            (None, None, None, None) => {}
            _ => anyhow::bail!("replay buffer: actor observations given to a buffer that keeps none, or missing"),
        }
        // each array into the scratch buffer, then from there into its ring's slot
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        let mut sources = Vec::with_capacity(pairs.len());
        let mut at = 0u64;
        let mut moves = Vec::with_capacity(pairs.len());
        for (ring, x) in pairs {
            ensure!(x.dims() == [n, ring.dim], "replay buffer: `{}` of shape {:?} for {n} envs × {}", ring.name, x.dims(), ring.dim);
            let src = tensor_buffer(x)?;
            let bytes = (4 * n * ring.dim) as u64;
            enc.copy_buffer_to_buffer(src.buffer(), src.offset(), &self.scratch, at, bytes);
            moves.push((at, ring, bytes));
            at += bytes;
            sources.push(src);
        }
        for (from, ring, bytes) in moves {
            // the slot's piece, and the slot inside it
            let piece = &ring.pieces[slot / ring.slots_per_piece];
            enc.copy_buffer_to_buffer(&self.scratch, from, piece.buffer(), piece.offset() + (slot % ring.slots_per_piece) as u64 * bytes, bytes);
        }
        // the step's tensors are computed, and earlier samples read the rings, before these copies
        flush(&self.device)?;
        self.ctx.submit(enc, "replay buffer push (device-resident)")
    }

    /// A gradient step's rows from the rings: the rows `draw` picks and their n-step windows
    /// (discount `gamma`), the observations normalised by `norms` when `normalize` (the actor's
    /// taken from the head of the critic's, `obs_dim` columns, where the buffer keeps none). On
    /// burn's wgpu runtime as kernels of ours (`learn::kernels::replay_sample`: a launch per ring
    /// piece for each array, one for the windows, where [`DeviceReplay::sample`]'s tensor ops and
    /// the normaliser's launched ~17 kernels per window step and ~25 more); the tensor ops where a
    /// kernel cannot bind its tensors.
    pub fn sample_batch(&self, draw: &Draw, gamma: f64, obs_dim: usize, norms: &DeviceNormalizers, normalize: bool) -> Result<SampledBatch> {
        if let Ok(batch) = self.sample_batch_kernels(draw, gamma, obs_dim, norms, normalize) {
            return Ok(batch);
        }
        let b = draw.batch;
        let (obs, priv_obs, actions, returns, bootstrap, next_obs, next_priv) = self.sample(draw, gamma)?;
        // the actor's observations: kept, or the clean ones at the head of the critic's
        let actor_rows = |kept: Option<Tensor<2>>, critic: &Tensor<2>| kept.unwrap_or_else(|| critic.clone().slice([0..b, 0..obs_dim]));
        let (obs, next_obs) = (actor_rows(obs, &priv_obs), actor_rows(next_obs, &next_priv));
        Ok(SampledBatch {
            obs: norms.obs.normalized(obs, normalize),
            next_obs: norms.obs.normalized(next_obs, normalize),
            priv_obs: norms.priv_obs.normalized(priv_obs, normalize),
            next_priv: norms.priv_obs.normalized(next_priv, normalize),
            actions,
            returns,
            bootstrap,
        })
    }

    /// [`DeviceReplay::sample_batch`] as kernels of ours: the rows and flags uploaded once, the
    /// three flag rings gathered into one `[3 · n_step · B, 1]` tensor, the windows walked, then
    /// each array's rows gathered (and normalised) from the first row of each window or its last.
    fn sample_batch_kernels(&self, draw: &Draw, gamma: f64, obs_dim: usize, norms: &DeviceNormalizers, normalize: bool) -> Result<SampledBatch> {
        use crate::learn::kernels::replay_sample::{GatherNorm, empty_like, gather_into, tensor_of, upload_rows, windows};
        let b = draw.batch;
        let n_step = draw.valid.len() / b.max(1);
        let nb = n_step * b;
        ensure!(b > 0 && n_step > 0 && draw.window.len() == nb, "SAC's device-resident batch: {} window rows and {} flags for a batch of {b}", draw.window.len(), draw.valid.len());
        let mut idx = Vec::with_capacity(2 * nb);
        for &r in &draw.window {
            idx.push(u32::try_from(r).context("SAC's device-resident batch: a ring row over 32 bits")?);
        }
        idx.extend(draw.valid.iter().map(|&v| v as u32));
        let idx = upload_rows(&idx, &self.device)?; // [2 · n_step · B]: window rows, then written flags
        let like = &self.priv_obs.pieces[0].tensor;
        let (po, pp) = (&norms.obs, &norms.priv_obs);
        let raw = GatherNorm { mean: &pp.mean, scale: &pp.scale, apply: false };
        // the rewards, done and terminated flags of every window step's row
        let flags = empty_like(like, 3 * nb, 1)?;
        for (k, ring) in [&self.rewards, &self.done, &self.terminated].into_iter().enumerate() {
            gather_into(&idx, nb, &ring_view(ring), 1, &raw, &flags, k * nb)?;
        }
        let (returns, bootstrap, last) = windows(&idx, &flags, b, n_step, gamma)?;
        // each array's rows: from the windows' first rows (idx's first B) or their last
        let gather = |rows: &Tensor<2>, ring: &Ring, cols: usize, norm: &GatherNorm<'_>| -> Result<Tensor<2>> {
            let out = empty_like(like, b, cols)?;
            gather_into(rows, b, &ring_view(ring), cols, norm, &out, 0)?;
            Ok(tensor_of(out))
        };
        let obs_norm = GatherNorm { mean: &po.mean, scale: &po.scale, apply: normalize };
        let priv_norm = GatherNorm { mean: &pp.mean, scale: &pp.scale, apply: normalize };
        // the actor's observations: kept, or the head of the critic's
        let (obs_ring, next_obs_ring) = (self.obs.as_ref().unwrap_or(&self.priv_obs), self.next_obs.as_ref().unwrap_or(&self.next_priv_obs));
        Ok(SampledBatch {
            obs: gather(&idx, obs_ring, obs_dim, &obs_norm)?,
            next_obs: gather(&last, next_obs_ring, obs_dim, &obs_norm)?,
            priv_obs: gather(&idx, &self.priv_obs, self.priv_obs.dim, &priv_norm)?,
            next_priv: gather(&last, &self.next_priv_obs, self.next_priv_obs.dim, &priv_norm)?,
            actions: gather(&idx, &self.actions, self.actions.dim, &raw)?,
            returns,
            bootstrap,
        })
    }

    /// The rows `draw` picks and their n-step windows (discount `gamma`) as tensor ops (the
    /// reference of [`DeviceReplay::sample_batch`]'s kernels, and their fallback): raw actor observations
    /// (None without them), critic observations and actions of the first transition, the return
    /// and bootstrap factor `[B, 1]`, and the raw observations after the window.
    #[allow(clippy::type_complexity)]
    pub fn sample(&self, draw: &Draw, gamma: f64) -> Result<(Option<Tensor<2>>, Tensor<2>, Tensor<2>, Tensor<2>, Tensor<2>, Option<Tensor<2>>, Tensor<2>)> {
        let b = draw.batch;
        let n_step = draw.valid.len() / b.max(1);
        let dev = &self.device;
        let rows = |w: usize| -> Tensor<1, Int> {
            let idx: Vec<i32> = draw.window[w * b..(w + 1) * b].iter().map(|&r| r as i32).collect();
            crate::host_traffic::add(4 * b as u64);
            crate::gpu_counts::add(crate::gpu_counts::Event::Upload, "burn:from_data (replay rows)");
            Tensor::<1, Int>::from_data(TensorData::new(idx, [b]), dev)
        };
        let valid = |w: usize| to_tensor(draw.valid[w * b..(w + 1) * b].iter().map(|&v| v as u8 as f32).collect(), [b, 1], dev);
        let gather = |r: &Ring, idx: &Tensor<1, Int>| r.gather(idx);
        let first = rows(0);
        // buffer.rs's window walk as masks: `ok` while the window goes on and the slot is written
        let mut ret = Tensor::<2>::zeros([b, 1], dev);
        let mut disc = Tensor::<2>::ones([b, 1], dev);
        let mut alive = Tensor::<2>::ones([b, 1], dev);
        let mut last = first.clone();
        for w in 0..n_step {
            let idx = if w == 0 { first.clone() } else { rows(w) };
            let ok = alive.clone() * valid(w); // [B, 1]
            let (r, done, term) = (gather(&self.rewards, &idx), gather(&self.done, &idx), gather(&self.terminated, &idx));
            ret = ret + ok.clone() * disc.clone() * r; // R += γᵏ r
            last = last.mask_where(ok.clone().reshape([b]).greater_elem(0.5), idx);
            disc = disc * ok.clone().mul_scalar(gamma - 1.0).add_scalar(1.0); // γᵏ⁺¹ where the window went on
            disc = disc * (ok.ones_like() - ok.clone() * term); // 0 after a termination (no bootstrap)
            alive = alive * (ok.ones_like() - ok * done); // the window stops at an episode's end
        }
        let obs = self.obs.as_ref().map(|r| gather(r, &first));
        let next_obs = self.next_obs.as_ref().map(|r| gather(r, &last));
        Ok((obs, gather(&self.priv_obs, &first), gather(&self.actions, &first), ret, disc, next_obs, gather(&self.next_priv_obs, &last)))
    }

    /// A host buffer with `host`'s counters and the written rows of the device rings (for a
    /// checkpoint).
    pub fn to_host(&self, host: &ReplayBuffer) -> Result<ReplayBuffer> {
        let mut out = ReplayBuffer::new(host.envs, host.capacity, host.obs_dim, host.priv_dim, host.act_dim);
        let rows = host.len * host.envs;
        out.pos = host.pos;
        out.len = host.len;
        if rows == 0 {
            return Ok(out);
        }
        // the written rows, piece by piece
        let read = |r: &Ring| -> Result<Vec<f32>> {
            let mut all = Vec::with_capacity(rows * r.dim);
            for (piece, _, take) in r.written(rows) {
                all.extend(to_host(piece.tensor.clone().slice([0..take, 0..r.dim]))?);
            }
            Ok(all)
        };
        let copy = |dst: &mut Vec<f32>, v: Vec<f32>| dst[..v.len()].copy_from_slice(&v);
        if let (Some(o), Some(no)) = (&self.obs, &self.next_obs) {
            copy(&mut out.obs, read(o)?);
            copy(&mut out.next_obs, read(no)?);
        }
        copy(&mut out.priv_obs, read(&self.priv_obs)?);
        copy(&mut out.next_priv_obs, read(&self.next_priv_obs)?);
        copy(&mut out.actions, read(&self.actions)?);
        copy(&mut out.rewards, read(&self.rewards)?);
        for (dst, ring) in [(&mut out.done, &self.done), (&mut out.terminated, &self.terminated)] {
            for (d, v) in dst.iter_mut().zip(read(ring)?) {
                *d = (v != 0.0) as u8;
            }
        }
        Ok(out)
    }

    /// Writes the written rows of `host` into the device rings (a resumed run).
    pub fn load(&self, host: &ReplayBuffer) -> Result<()> {
        let rows = host.len * host.envs;
        if rows == 0 {
            return Ok(());
        }
        // burn's zero fills of the rings land before these writes
        flush(&self.device)?;
        let write = |r: &Ring, v: &[f32]| -> Result<()> {
            for (piece, start, take) in r.written(rows) {
                self.ctx.upload_at(r.name, piece.buffer(), piece.offset(), bytemuck::cast_slice(&v[start * r.dim..(start + take) * r.dim]))?;
            }
            Ok(())
        };
        if let (Some(o), Some(no)) = (&self.obs, &self.next_obs) {
            write(o, &host.obs)?;
            write(no, &host.next_obs)?;
        }
        write(&self.priv_obs, &host.priv_obs)?;
        write(&self.next_priv_obs, &host.next_priv_obs)?;
        write(&self.actions, &host.actions)?;
        write(&self.rewards, &host.rewards)?;
        let flags = |v: &[u8]| v[..rows].iter().map(|&x| x as f32).collect::<Vec<f32>>();
        write(&self.done, &flags(&host.done))?;
        write(&self.terminated, &flags(&host.terminated))
    }

    /// Bytes of device memory the rings hold.
    pub fn bytes(&self) -> u64 {
        self.rings().iter().map(|r| r.size()).sum()
    }
}

/// The first half of a transition, kept from `act_device` to `observe_device` (raw, `[N, ·]`).
struct DevicePending {
    obs: Tensor<2>,
    priv_obs: Tensor<2>,
    actions: Tensor<2>,
}

/// What a device-resident SAC holds beside [`Sac`]'s networks.
pub struct DeviceSac {
    noise: DeviceNoise,
    /// The observation normalisers.
    pub(crate) norms: DeviceNormalizers,
    replay: DeviceReplay,
    pending: Option<DevicePending>,
}

impl DeviceSac {
    /// The replay buffer on the host, with `host`'s counters (for a checkpoint).
    pub fn buffer_on_host(&self, host: &ReplayBuffer) -> Result<ReplayBuffer> {
        self.replay.to_host(host)
    }

    /// Writes `host`'s written rows into the device buffer (a resumed run).
    pub fn load_buffer(&mut self, host: &ReplayBuffer) -> Result<()> {
        self.pending = None;
        self.replay.load(host)
    }
}

impl Sac {
    /// From now on the replay buffer and the env loop's tensors stay on the learner device, which
    /// must be burn's wgpu runtime on `ctx`'s device (the simulator's): [`Sac::act_device`] and
    /// [`Sac::observe_device`] replace `act` and `observe`. The host buffer keeps the slot counters
    /// (its arrays are never written: the OS gives their pages only when written). Returns the
    /// device buffer's bytes.
    pub fn start_device_rollouts(&mut self, ctx: &GpuContext) -> Result<u64> {
        ensure!(self.pending.is_none(), "device-resident rollouts must start between env steps");
        ensure!(crate::learn::nets::is_gpu(&self.device), "device-resident rollouts need burn's wgpu learner (train.device = gpu)");
        let dims = self.dims;
        let b = self.cfg.batch_size as usize;
        let noise = DeviceNoise::new(ctx, &self.device, (self.buffer.envs * dims.act).max(2 * b * dims.act))?;
        let replay = DeviceReplay::new(ctx, &self.device, &self.buffer, self.cfg.device_piece_bytes)?;
        replay.load(&self.buffer)?;
        let bytes = replay.bytes();
        let norms = DeviceNormalizers::from_host(&self.obs_norm, &self.priv_norm, &self.device);
        self.on_device = Some(DeviceSac { noise, norms, replay, pending: None });
        Ok(bytes)
    }

    /// As [`Sac::act`] on the device: training actions `[N, A]` for raw observations `obs` `[N, O]`
    /// and `priv_obs` `[N, P]` (the normalisers merge them first).
    pub fn act_device(&mut self, obs: &Tensor<2>, priv_obs: &Tensor<2>) -> Result<Tensor<2>> {
        let d = self.dims;
        let n = self.buffer.envs;
        ensure!(obs.dims() == [n, d.obs] && priv_obs.dims() == [n, d.priv_obs], "observation sizes do not match the learner");
        let (seed, draw, normalize, random) = (self.noise_seed, self.noise_draw, self.normalize, self.env_steps < self.cfg.random_steps as u64);
        self.noise_draw = draw.wrapping_add(1);
        let dv = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("act_device() before start_device_rollouts()"))?;
        // merged first, then applied (the critic's normalised observations are not needed here)
        let (obs_n, _) = dv.norms.update_and_normalize(obs, priv_obs, normalize)?;
        let actions = if random {
            dv.noise.uniforms(seed, draw, n, d.act)? // a ~ U[−1, 1)
        } else {
            let x = Tensor::from_inner(obs_n);
            let params: Vec<Tensor<2>> = self.actor.iter().map(|p| p.clone().inner()).collect();
            let eps = dv.noise.normals(seed, draw, n, d.act)?; // ε ~ N(0, 1) [N, A]
            let (mu, log_std) = self.policy(&params, x);
            (mu.inner() + log_std.inner().exp() * eps).tanh() // a = tanh(μ + σ ε)
        };
        let dv = self.on_device.as_mut().expect("checked above");
        dv.pending = Some(DevicePending { obs: obs.clone(), priv_obs: priv_obs.clone(), actions: actions.clone() });
        Ok(actions)
    }

    /// As [`Sac::observe`] on the device: rewards, terminations and time-outs `[N, 1]` (flags 0 or
    /// 1), the observations after the step and the final ones of the envs that ended.
    #[allow(clippy::too_many_arguments)]
    pub fn observe_device(&mut self, rewards: &Tensor<2>, terminated: &Tensor<2>, time_outs: &Tensor<2>, next_obs: &Tensor<2>, next_priv_obs: &Tensor<2>, final_obs: &Tensor<2>, final_priv_obs: &Tensor<2>) -> Result<()> {
        let (scale, store) = (self.cfg.reward_scale as f64, self.cfg.store_actor_obs);
        let slot = self.buffer.pos;
        let dv = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("observe_device() before start_device_rollouts()"))?;
        let p = dv.pending.take().ok_or_else(|| anyhow::anyhow!("observe_device() without act_device()"))?;
        let done = (terminated.clone() + time_outs.clone()).clamp(0.0, 1.0); // [N, 1]
        // the observation after the step: an ended episode's final one, else the next step's
        // (x (1 − d) + f d is exact for d ∈ {0, 1})
        let keep = done.ones_like() - done.clone();
        let pick = |next: &Tensor<2>, fin: &Tensor<2>| next.clone() * keep.clone() + fin.clone() * done.clone();
        let next_p = pick(next_priv_obs, final_priv_obs);
        let next_o = store.then(|| pick(next_obs, final_obs));
        let scaled = rewards.clone().mul_scalar(scale);
        dv.replay.push(
            slot,
            &super::device::DeviceTransitions {
                obs: store.then_some(&p.obs),
                priv_obs: &p.priv_obs,
                actions: &p.actions,
                rewards: &scaled,
                done: &done,
                terminated,
                next_obs: next_o.as_ref(),
                next_priv_obs: &next_p,
            },
        )?;
        self.buffer.advance();
        self.env_steps += 1;
        if self.env_steps >= self.cfg.learning_starts.max(1) as u64 {
            for _ in 0..self.cfg.updates_per_step {
                self.gradient_step()?;
            }
        }
        Ok(())
    }

    /// A gradient step's batch from the device buffer (noise draws `draws`: the target's, the
    /// actor's): the host buffer's draw of rows, the windows on the device.
    pub(super) fn device_batch(&mut self, draws: (u32, u32)) -> Result<GradBatch> {
        let (d, b, n_step) = (self.dims, self.cfg.batch_size as usize, self.cfg.n_step as usize);
        let draw = self.buffer.draw(b, n_step, &mut self.rng)?;
        let (seed, normalize) = (self.noise_seed, self.normalize);
        let dv = self.on_device.as_ref().ok_or_else(|| anyhow::anyhow!("a device batch before start_device_rollouts()"))?;
        let s = dv.replay.sample_batch(&draw, self.cfg.gamma as f64, d.obs, &dv.norms, normalize)?;
        let lift = Tensor::from_inner; // untracked, on the autodiff device, as the host path's uploads
        // both draws in one kernel: rows 0..B the target's (draws.0), B..2B the actor's (draws.1)
        ensure!(draws.1 == draws.0.wrapping_add(1), "a gradient step's noise draws must be consecutive");
        let noise = dv.noise.normals_block(seed, draws.0, 2, b, d.act)?; // [2B, A]
        Ok(GradBatch {
            obs: lift(s.obs),
            next_obs: lift(s.next_obs),
            priv_obs: lift(s.priv_obs),
            next_priv: lift(s.next_priv),
            actions: lift(s.actions),
            returns: s.returns,
            bootstrap: s.bootstrap,
            eps_actor: lift(noise.clone().narrow(0, b, b)),
            eps_next: noise.narrow(0, 0, b),
        })
    }
}
