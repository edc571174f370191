%
(Full-width slot, 10 mm wide, ap 1 mm, Al 2024-T6, Duan 2025 conditions:)
(1200 rpm, 500 mm/min. Enters from outside the stock at x = -10.)
G21 G90 G17
G64 P0.01
S1200 M3
G0 X-10 Y0 Z5
G0 Z-1
G1 X50 Y0 F500
G0 Z5
M5
M30
%
