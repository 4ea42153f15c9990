"""GTSAM's Levenberg-Marquardt on a g2o file, as the reference for `cargo bench -p slam`.

Usage: gtsam_lm.py FILE.g2o 2|3  — prints one JSON object: initial and final error (GTSAM's error
is half the chi²), iterations and the optimisation time in seconds. A tight prior fixes pose 0.
"""
import json
import sys
import time

import gtsam
import numpy as np

path, dim = sys.argv[1], int(sys.argv[2])
graph, initial = gtsam.readG2o(path, dim == 3)
if dim == 3:
    graph.add(gtsam.PriorFactorPose3(0, initial.atPose3(0), gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-6))))
else:
    graph.add(gtsam.PriorFactorPose2(0, initial.atPose2(0), gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 1e-6))))
params = gtsam.LevenbergMarquardtParams()
t = time.perf_counter()
optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
result = optimizer.optimize()
elapsed = time.perf_counter() - t
print(json.dumps({
    "initial_error": graph.error(initial),
    "final_error": graph.error(result),
    "iterations": optimizer.iterations(),
    "time_s": elapsed,
}))
