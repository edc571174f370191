# twin_force_calibrate: `twin calibrate` on dynamometer force logs (coefficients, runout, effects).
add_library(twin_force_calibrate STATIC analysis/force_calibrate.cpp)
target_link_libraries(twin_force_calibrate PUBLIC twin::analysis Eigen3::Eigen fmt::fmt PRIVATE twin::warnings)
add_library(twin::force_calibrate ALIAS twin_force_calibrate)
target_link_libraries(twin PRIVATE twin_force_calibrate)
