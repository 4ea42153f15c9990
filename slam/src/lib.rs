//! Multi-robot RGB-D SLAM: one pose graph for every camera of every robot.
//!
//! * [`features`], [`frontend`]: ORB-like features with depth, pairwise registration;
//! * [`place`]: place recognition for loop-closure candidates;
//! * [`system`]: the SLAM itself — tracking, keyframes, loop closure within and across robots,
//!   coordinate frames anchored by inter-robot matches, background optimisation;
//! * [`posegraph`], [`optimize`], [`incremental`]: pose graphs (g2o) and their optimisation;
//! * [`occupancy`], [`livemap`]: the 3D voxel map, its 2D projection, and its rebuild when the
//!   graph moves;
//! * [`ekf`]: the pose filter that feeds controllers between camera frames;
//! * [`depth_odometry`]: the motion a depth image's walls measure when the camera sees no
//!   texture;
//! * [`dataset`], [`trajectory`], [`eval`]: recorded sequences, TUM trajectories, ATE and RPE.

pub mod dataset;
pub mod depth_odometry;
pub mod ekf;
pub mod eval;
pub mod features;
pub mod frontend;
pub mod incremental;
pub mod livemap;
pub mod occupancy;
pub mod optimize;
pub mod place;
pub mod posegraph;
pub mod rigid;
pub mod system;
pub mod trajectory;
