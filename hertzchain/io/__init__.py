"""File formats: what hertzchain reads and writes.

- `hertzchain.io.tracefile`: the trace-file format `hertzchain-trace/1` (recorded or
  synthetic experiments as CSV).
- `hertzchain.io.scopefiles`: oscilloscope files read into `Waveforms`.
- `hertzchain.io.importer`: experiment files (`experiment.toml`) that turn a lab's scope
  files into trace files.
- `hertzchain.io.summary`: the machine-readable summary of one run.
- `hertzchain.io.atomic`: output files and folders written whole or not at all.
"""
