"""spooflens: forensic analysis of GNSS spoofing in vehicle logs.

Pipeline: file -> readers -> EpochTable -> navigation -> detectors -> verdict -> Rerun recording and report.
"""

__version__ = "0.1.0"
