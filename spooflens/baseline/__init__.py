"""A vehicle's baseline: what its clean logs say is normal (`spooflens baseline LOG... -o V.baseline.json`),
so that a log attacked from its first fix to its last still shows it (`analyze --baseline V.baseline.json`).

- `format`: the versioned JSON file, defined once (schema in docs/baseline.md);
- `identity`: receiver model, firmware and IMU of a log, checked against the baseline's;
- `measure`, `learn`: from analysed clean logs to a baseline;
- `use`: what each detector takes from a baseline;
- `command`: the CLI command.
"""
