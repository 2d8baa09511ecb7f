"""Evaluation: the field's metrics (OTB single target, MOT via motmetrics, detection rates), plots, `evaluate`."""
