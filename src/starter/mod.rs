//! `dextrain new`: starter configs for a hand or an object that has none.
//!
//! - `dextrain new hand URDF` ([`hand`]): the lift task of configs/lift_cube_cpu.toml with this
//!   hand: fingertips, thumb, wrist orientation and height, mesh colliders, missing joint limits
//!   and the palm point guessed from the URDF and from a grasp planned and replayed for it.
//! - `dextrain new object MESH` ([`object`]): the same task with the object from a mesh (mass from
//!   its volume) and the hand of another config (dexhand16's by default).
//!
//! Every guess is printed (stderr) with its reason, and the file carries the same reasons as
//! comments. Paths in the file are relative to its own folder (how `Config::resolve` reads them),
//! so it works wherever it is written. The text is checked as `dextrain check` checks a config
//! (parsed and validated, the hand and objects loaded, the task set up) before it is written, and
//! it is written whole or not at all ([`output::write_atomic`]); an existing file is refused
//! without `--force`. The file's fixed sections come from [`template`]; the wrist's pose rule is
//! [`pose`]'s.

/// Which links are the fingertips, which is the thumb.
pub mod fingers;
/// `dextrain new hand`.
pub mod hand;
/// `dextrain new object`.
pub mod object;
/// Where the file goes and how it is written.
pub mod output;
/// The wrist's initial orientation and height.
pub mod pose;
/// The config's text.
pub mod template;

use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::config::Config;
use crate::env::SimModel;

/// `dextrain new`: which starter config to write.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum NewCommand {
    /// Write a starter lift config (configs/lift_cube_cpu.toml's task and learner) for a hand
    /// URDF: fingertips, thumb, wrist pose, colliders and palm point guessed and said.
    Hand(NewHandArgs),
    /// Write a starter lift config for an object mesh (OBJ or STL) with the hand of another
    /// config: the mesh's path, units and mass guessed and said.
    Object(NewObjectArgs),
}

/// Arguments of `dextrain new hand`.
#[derive(clap::Args, Debug, Clone)]
pub struct NewHandArgs {
    /// The hand's URDF.
    pub urdf: PathBuf,
    /// The config file to write (default: `<URDF stem>_lift.toml` in the current directory); its
    /// folders are made. `hand.urdf` is written relative to its folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Overwrite the config file if it exists (else that is an error and the file is left as it is).
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `dextrain new object`.
#[derive(clap::Args, Debug, Clone)]
pub struct NewObjectArgs {
    /// The object's mesh: an OBJ file (each group/object one convex piece) or an STL file.
    pub mesh: PathBuf,
    /// The config whose `[hand]`, `[wrist]` and `[task.hand]` the starter copies (default:
    /// configs/lift_cube_cpu.toml, dexhand16, in the current directory or the source checkout).
    #[arg(long)]
    pub hand_config: Option<PathBuf>,
    /// The config file to write (default: `<object name>_lift.toml` in the current directory);
    /// its folders are made. Paths in it are relative to its folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Overwrite the config file if it exists (else that is an error and the file is left as it is).
    #[arg(long)]
    pub force: bool,
    /// The object's mass (kg). Default: 1000 kg/m³ (water's) × the mesh's volume.
    #[arg(long)]
    pub mass: Option<f32>,
    /// Factor on the mesh's coordinates (0.001 for millimetres). Default: 1, or 0.001 for a mesh
    /// more than 1 unit across.
    #[arg(long)]
    pub mesh_scale: Option<f32>,
}

/// `dextrain new hand` or `dextrain new object`; prints the written file's path (stdout). A
/// command that fails leaves no folder it made for `--out` (the folders are made before the text is
/// checked, since its relative paths resolve from there).
pub fn run(cmd: &NewCommand) -> Result<()> {
    let out = match cmd {
        NewCommand::Hand(args) => args.out.as_deref(),
        NewCommand::Object(args) => args.out.as_deref(),
    };
    // the folders above `out` that do not exist yet, deepest first
    let missing: Vec<PathBuf> = out.map(|o| o.ancestors().skip(1).filter(|a| !a.as_os_str().is_empty()).take_while(|a| !a.exists()).map(Path::to_path_buf).collect()).unwrap_or_default();
    let written = match cmd {
        NewCommand::Hand(args) => hand::new_hand(args).map(|h| h.path),
        NewCommand::Object(args) => object::new_object(args).map(|o| o.path),
    };
    match written {
        Ok(path) => {
            crate::console::result(&path.display().to_string());
            Ok(())
        }
        Err(e) => {
            // remove_dir removes only empty folders: nothing but what this command made goes
            for dir in &missing {
                let _ = std::fs::remove_dir(dir);
            }
            Err(e)
        }
    }
}

/// What `dextrain check` does to a config, on the text about to be written to `out`: parse and
/// validate it, load the hand and the objects, set the task up. The folder of `out` is made
/// first (relative paths in the text resolve from it).
pub fn check_text(text: &str, out: &Path) -> Result<(Config, SimModel)> {
    crate::files::create_parent_dir(out)?;
    let cfg = Config::from_toml_str(text, out)?;
    let model = SimModel::from_config(&cfg)?;
    crate::task::task_setup(&cfg, &model)?;
    Ok((cfg, model))
}

/// [`check_text`], then the text written to `out` whole ([`output::write_atomic`]).
pub fn check_and_write(text: &str, out: &Path, force: bool) -> Result<()> {
    check_text(text, out).map_err(|e| anyhow::anyhow!("{}: the starter config does not pass `dextrain check`: {e:#}", out.display()))?;
    output::write_atomic(out, text, force)
}
