# `twin export-fmu`: writes the FMU archive; the FMU binaries
# (fmu/fmi2/MachineTwin.so, fmu/fmi3/MachineTwin.so) are built alongside and
# their paths compiled in (--binary overrides them).
target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_export_fmu.cpp)
target_compile_definitions(twin PRIVATE TWIN_FMU_BINARY="$<TARGET_FILE:MachineTwin>"
                                        TWIN_FMU3_BINARY="$<TARGET_FILE:MachineTwin3>")
target_link_libraries(twin PRIVATE twin_fmu_common nlohmann_json::nlohmann_json)
add_dependencies(twin MachineTwin MachineTwin3)
