# `twin export-fmu`: writes the FMU archive; the FMU binary (fmu/MachineTwin.so)
# is built alongside and its path compiled in (--binary overrides it).
target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_export_fmu.cpp)
target_compile_definitions(twin PRIVATE TWIN_FMU_BINARY="$<TARGET_FILE:MachineTwin>")
target_link_libraries(twin PRIVATE twin_fmu_common PkgConfig::LIBZIP yaml-cpp nlohmann_json::nlohmann_json)
add_dependencies(twin MachineTwin)
