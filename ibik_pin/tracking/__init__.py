"""A recorded sequence solved frame after frame: the tracker and its priority levels (tracker), the
swivel search of free elbows and knees (swivel), the TRC axis convention (axes), `ibik track` from
files to outputs (pipeline) and its report.json (report)."""
