# noqa: A005 - the package name io (ssm_localization.io) shadows no import of ours
"""Data in and out: rosbag2 bags, CARMEN logs, simulated scans."""
