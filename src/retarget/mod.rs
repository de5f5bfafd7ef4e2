//! Human demonstrations to robot hands (issue 39): a human hand's keypoints, frame by frame,
//! retargeted to the wrist pose and joint angles of a robot hand.
//!
//! - `demo.rs`: a human demonstration (21 keypoints and the object's pose per frame, the frame
//!   rate, the frame they are in) and DexMV's `.npz` layout read into it (`traj::npy`);
//! - `solve.rs`: the per-frame solve (dex-retargeting's vector method: keypoint vectors of the
//!   robot matched to the human's, scaled; joint limits; a pull toward the previous frame; warm
//!   starts) and its per-keypoint errors.
//!
//! Not here yet (issue 39): our own keypoint formats (MCAP and CSV),
//! the world frame estimated from the demo, the human-to-robot keypoint tables of the shipped hands,
//! the contact clean-up, and the `dextrain traj retarget` command that writes a reference.

pub mod demo;
pub mod solve;
