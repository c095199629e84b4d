"""Pure numerics of the feeder: contact model, surface, strokes, particle dynamics.

No rclpy, no file I/O, no wall clock: usable alone and from the offline commands.
"""
