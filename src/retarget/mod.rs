//! Human demonstrations to robot hands (issue 39): a human hand's keypoints, frame by frame,
//! retargeted to the wrist pose and joint angles of a robot hand.
//!
//! - `demo.rs`: a human demonstration (21 keypoints and the object's pose per frame, the frame
//!   rate, the frame they are in), DexMV's `.npz` layout and dextrain's CSV and MCAP read into it;
//! - `world.rs`: a camera-frame demonstration's world frame (up and the table from the object at
//!   rest), put on the config's table;
//! - `keypoint_map.rs`: which human keypoint goes to which point of a robot hand (from the hand's
//!   fingertips and their chains), and the robot's size over the human's;
//! - `solve.rs`: the per-frame solve (dex-retargeting's vector method: keypoint vectors of the
//!   robot matched to the human's, scaled; joint limits; a pull toward the previous frame; warm
//!   starts) and its per-keypoint errors;
//! - `contact.rs`: the contact clean-up: the object's path cleaned, the grasp (the human's
//!   re-grounded on the object, or `traj synth`'s planned one) closed on the object's surface and
//!   carried along its path, the approach kept off the table and the object;
//! - `command.rs`: `dextrain traj retarget`, which writes the reference.


pub mod command;
pub mod contact;
pub mod demo;
pub mod keypoint_map;
pub mod solve;
pub mod world;
