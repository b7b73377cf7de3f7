"""From a CSV record to model probabilities and a figure of the fits, in Python.

    python examples/python_quickstart.py data/demo.csv fit.png
"""

import sys

import pandas as pd

import bitrock
import bitrock.plot

frame = pd.read_csv(sys.argv[1])                      # time_s, bit_speed_rpm, torque_knm, wob_kn
record = bitrock.read_record(frame)                   # columns and units found by their names
result = bitrock.abc(record, particles=2000, seed=1, progress=False)
print(result.model_probabilities.round(3))            # population × law, with ε
print(result.summary().round(3))                      # posterior of each law's parameters
ax = bitrock.plot.fit(result)                         # the record, each law's fit and 98 % band
ax.figure.savefig(sys.argv[2], dpi=110)
