# twin_sweep: `twin sweep`, independent cases on local processes or, when
# Open MPI is found (optional), across MPI ranks.
add_library(twin_sweep STATIC sweep/sweep_spec.cpp sweep/runner.cpp)
target_link_libraries(twin_sweep PUBLIC twin::io nlohmann_json::nlohmann_json fmt::fmt PRIVATE twin::warnings)
option(TWIN_WITH_MPI "build `twin sweep` with MPI when an MPI library is found" ON)
if(TWIN_WITH_MPI)
  find_package(MPI COMPONENTS C)
endif()
if(TWIN_WITH_MPI AND MPI_C_FOUND)
  target_link_libraries(twin_sweep PRIVATE MPI::MPI_C)
  # The C interface only: no C++ bindings (OMPI_SKIP_MPICXX, MPICH_SKIP_MPICXX).
  target_compile_definitions(twin_sweep PRIVATE TWIN_WITH_MPI=1 OMPI_SKIP_MPICXX=1 MPICH_SKIP_MPICXX=1)
  message(STATUS "twin sweep: with MPI (${MPI_C_LIBRARIES})")
else()
  target_compile_definitions(twin_sweep PRIVATE TWIN_WITH_MPI=0)
  message(STATUS "twin sweep: without MPI (local cores only)")
endif()
add_library(twin::sweep ALIAS twin_sweep)

target_sources(twin PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli/cmd_sweep.cpp)
target_link_libraries(twin PRIVATE twin_sweep)
# Tests run the MPI path only when the build has it.
if(TWIN_WITH_MPI AND MPI_C_FOUND)
  set_property(GLOBAL PROPERTY TWIN_SWEEP_MPIEXEC "${MPIEXEC_EXECUTABLE}")
else()
  set_property(GLOBAL PROPERTY TWIN_SWEEP_MPIEXEC "")
endif()
