"""The ROS side of the simulator worker, in parts the node (``simulator_node``) composes:

* ``commands``: reads ``cmd_vel`` straight from a wait set (lockstep speed);
* ``topics``: the robot-under-test publishers and the recording of what they send;
* ``stepping``: the tick loop (lockstep or clocked) of one episode, for a robot or a fleet;
* ``nav2_stack``: NavigateToPose goals and the per-episode costmap resets of a Nav2 stack;
* ``failure_bags``: the failure bag of an episode, with every setting it ran with.

The simulation itself (world, robot, sensors, metrics) is the ROS-free core in
``sessgan_sim.episode``; the node's parameters are ``sessgan_sim.simulator_settings``.
"""
