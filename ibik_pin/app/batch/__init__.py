"""`ibik batch`: every trial of a session tracked on Dask distributed, resumable, one row per trial.

discovery finds the trials, tasks holds what a worker runs, runner submits them to Dask, summary
writes the table; command is the CLI's part. Dask is the optional extra `ibik_pin[batch]`.
"""
