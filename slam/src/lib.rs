//! Multi-robot RGB-D SLAM. So far: trajectories (TUM format) and their evaluation (ATE, RPE).

pub mod eval;
pub mod trajectory;
