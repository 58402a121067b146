"""ROS 2 (docs/ros2.md): the driver of a robot run by ros2_control (``wmm-qp driver ros2``), a
stand-in ROS 2 robot on the sim (``wmm-qp sim --ros2``) and the daemon's ROS 2 face
(``wmm-qp serve --ros2``).

``rclpy`` and ROS 2's message packages are imported here only (``tools/check_layers.py``): every
other module loads without them (``pip install 'wmm-qp[ros2]'`` adds them). Only
:mod:`.sim_robot` imports the sim.
"""
