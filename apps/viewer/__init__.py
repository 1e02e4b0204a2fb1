"""``mjx-damage view``: MuJoCo's interactive viewer on native MuJoCo with live damage feedback.

One module each: :mod:`native_env` (a task stepped on native MuJoCo through its
own step), :mod:`feedback` (tint, health panel, water, heat glow), :mod:`keys`
(teleoperation key map), :mod:`episode` (recording in the dataset layout),
:mod:`display` (a private Xvfb screen and its screenshot), :mod:`app` (the loop).
The command line is :mod:`apps.view_cli`.
"""
