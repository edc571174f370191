%
(A straight wall cut at 500 mm/min, 1200 rpm, from inside the stock.)
G21 G90 G17
S1200 M3
G1 X-6 Y-5 F500
M5
M30
%
