%
(Production-like aluminium: 12000 rpm, 3 flutes, fz 0.1 mm -> 3600 mm/min,)
(side cut ae 3 mm, ap 6 mm along a wall and into a 90 deg inner corner.)
(Finished walls at x = 0 and y = 0, roughed to -3; tool centre on -6 = -R.)
G21 G90 G17
G64 P0.02
S12000 M3
G0 X-60 Y-6 Z5
G0 Z-6
G1 X-6 Y-6 F3600
G1 X-6 Y-40
G0 Z5
M5
M30
%
