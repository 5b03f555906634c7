"""Bring-up of a newly built robot: reference poses, servo calibration against them, pre-dive checks."""
