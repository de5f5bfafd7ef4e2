//! The old path of `dextrain train` (`dextrain::train::{TrainArgs, run}`), kept so that callers of
//! it keep building; the code is in `run/`.

pub use crate::run::TrainArgs;
pub use crate::run::train as run;
