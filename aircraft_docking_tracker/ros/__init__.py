"""The shared ROS node layer: the node base (parameters, QoS, diagnostics), message processing and
rejection counting, image markers."""
