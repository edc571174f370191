%
N10 G20 G90 T1 M3 S1000 (inch)
G1 X0.5 Y0.25 F20 ; comment
M5 M2
%
