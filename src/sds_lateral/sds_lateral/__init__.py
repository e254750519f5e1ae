"""The lateral camera (seed Sec. 3): a second, faster view of the container from the side.

`view` reads the lateral view file (camera file, frame rate, LED region, the checkerboard
placements that place the camera); `board` measures the camera's pose from its images of the
board at those places; `wall_profile` extracts the liquid's height along the wall, per frame,
in mm; `clock` links the side camera's clock to the top camera's by the LED (directly, and
through the Arduino); `comparison` evaluates the top camera's surface fit along the same wall
and compares.
"""
