%
(Air-cut square contour, 20 mm sides, counter-clockwise, with one 45 deg)
(chamfer corner: four blended corners of 90 deg and two of 45 deg at 1500 mm/min.)
G21 G90 G17
G64 P0.005
G1 X0 Y-20 F1500
G1 X0 Y0
G1 X-10 Y0
G1 X-20 Y-10
G1 X-20 Y-20
M30
%
