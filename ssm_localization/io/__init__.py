"""Data in and out: rosbag2 bags, CARMEN logs, simulated scans."""
