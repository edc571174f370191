# `twin cut`: the steady-cut calculator (process/steady_cut).
target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_cut.cpp)
