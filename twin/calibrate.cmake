# twin_calibrate: identification, residual diagnosis and effect choice for `twin calibrate`.
add_library(twin_calibrate STATIC analysis/signal.cpp analysis/identify.cpp analysis/diagnose.cpp
                                  analysis/effect_registry.cpp analysis/calibrate.cpp
                                  analysis/machine_from_data.cpp)
target_link_libraries(twin_calibrate PUBLIC twin::analysis Eigen3::Eigen fmt::fmt PRIVATE twin::warnings)
add_library(twin::calibrate ALIAS twin_calibrate)

target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_calibrate.cpp)
target_link_libraries(twin PRIVATE twin_calibrate)
