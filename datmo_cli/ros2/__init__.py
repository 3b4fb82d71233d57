"""datmo on a ROS 2 robot over DDS without ROS: the node, its parameters and its place in the graph."""
