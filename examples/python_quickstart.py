"""From a CSV record to model probabilities and a marginal posterior, in Python.

    python examples/python_quickstart.py data/demo.csv marginal.png
"""

import sys

import matplotlib.pyplot as plt
import pandas as pd

import bitrock

frame = pd.read_csv(sys.argv[1])                      # time_s, bit_speed_rpm, torque_knm, wob_kn
record = bitrock.read_record(frame)                   # columns and units found by their names
result = bitrock.abc(record, particles=2000, seed=1, progress=False)
print(result.model_probabilities.round(3))            # population × law, with ε
print(result.summary().round(3))                      # posterior of each law's parameters
params, weights = result.get_distribution("m2")       # as pyABC's History returns it
params["tsb"].plot.hist(weights=weights, bins=30, title="m2: static torque (kN·m)")
plt.savefig(sys.argv[2], dpi=100)
