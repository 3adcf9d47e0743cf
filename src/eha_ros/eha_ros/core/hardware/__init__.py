"""The plant side's hardware interface (ros2_control's hardware components, for one actuator).

One loop owner (nodes.plant_side) runs ``write(speed)`` then ``read()`` once per tick on a
backend: ``sim`` (core.plant.EhaPlant), ``ads`` (the drive's PLC over ADS) or ``mock``
(commands echoed into states, no physics). The command gate (core.hardware.gate) between the
controller and the backend is the loop's, the same for every backend.
"""
