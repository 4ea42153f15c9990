//! Multi-robot RGB-D SLAM: front end, pose graph, loop closure, occupancy, EKF. Not built yet: see issues #5 and #6.
