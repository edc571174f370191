%
(FADAL 2216 pocket corner: wall cut with radial depth ae 2 mm into and out of)
(a 90 deg inner corner, as Ozcan 2017 sec. 4; Duan 2025 conditions:)
(1200 rpm, 500 mm/min, ap 1 mm. Tool-tip coordinates relative to the part:)
(finished walls at x = 0 and y = 0, roughed to -2, tool centre on -5 = -R.)
(Enters from outside the stock at x = -50.)
G21 G90 G17
G64 P0.01
S1200 M3
G0 X-50 Y-5 Z5
G0 Z-1
G1 X-5 Y-5 F500
G1 X-5 Y-30
G0 Z5
M5
M30
%
