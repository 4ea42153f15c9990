//! Navigation for cooperative exploration, as plain functions over grids: inflation, frontiers,
//! cost matrices, Hungarian assignment, global and local planners, controllers, and the mission
//! planner step that ties them together (thesis §4.4, Algorithms 1–7).

pub mod assignment;
pub mod avoid;
pub mod blacklist;
pub mod clearance;
pub mod control;
pub mod frontier;
pub mod grid;
pub mod inflate;
pub mod local;
pub mod mission;
pub mod proximity;
pub mod render;
pub mod search;
pub mod sweep;
pub mod vantage;

pub use grid::{Cell, CellXY, Grid, MapError};
pub use mission::{Plan, PlanError, PlannerConfig, RobotPlan, Strategy, explored_part, plan};
