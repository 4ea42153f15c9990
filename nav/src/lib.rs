//! Navigation: grids, inflation, frontiers, Hungarian assignment, planners, controllers. Not built yet: see issue #4.
