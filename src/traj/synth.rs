//! `dextrain traj synth`: scripted approach–grasp–lift references.
