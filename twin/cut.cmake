# `twin cut` and the process section of scenarios.
if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_cut.cpp)
  target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_cut.cpp)
  target_compile_definitions(twin PRIVATE TWIN_HAVE_CUT)
endif()
