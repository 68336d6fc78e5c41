"""The application: `ibik track`, `ibik calibrate`, `ibik batch` and `ibik demo` from files to outputs.

The job (job), its inputs (video_inputs, silhouette_files, axes) and their checks (input_checks),
the run (track), what it writes (outputs, report, report_units, input_reports) into a folder
replaced only at the end (outdir); the subject's calibration (calibrate), the batch on Dask
(batch/) and the demo (demo). The top layer below the CLI: it may import every other part of
ibik_pin, and nothing else in ibik_pin imports it. Errors here name the command's options.
"""
