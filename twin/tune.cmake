# twin_tune: linear analysis of the position loops and gain tuning (`twin tune`).
find_package(NLopt REQUIRED)
add_library(twin_tune STATIC analysis/linear_analysis.cpp analysis/tune.cpp)
target_link_libraries(twin_tune PUBLIC twin::analysis Eigen3::Eigen PRIVATE NLopt::nlopt twin::warnings)
add_library(twin::tune ALIAS twin_tune)

target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_tune.cpp)
target_link_libraries(twin PRIVATE twin_tune)
