//! Multi-robot RGB-D SLAM. So far: pose graphs (g2o) and their optimisation (batch and
//! incremental in the background), trajectories (TUM format) and their evaluation (ATE, RPE).

pub mod eval;
pub mod incremental;
pub mod optimize;
pub mod posegraph;
pub mod trajectory;
