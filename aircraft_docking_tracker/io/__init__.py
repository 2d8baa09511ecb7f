"""Files: rosbag2-compatible MCAP bags (read, write, record, play) and MOTChallenge text files."""
