"""The contract between the control loop and its screens: the Snapshot, the view types and
the operator's commands."""
