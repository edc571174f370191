# cmake -DTWIN=... -DOUT=... [-DSCENARIO=...] [-DFMI=3] -P export_fmu.cmake
# Runs `twin export-fmu`; on failure it leaves OUT.error holding the message
# (the tests report it) instead of failing the build.
file(REMOVE ${OUT} ${OUT}.error)
set(args export-fmu -o ${OUT})
if(SCENARIO)
  list(APPEND args --scenario ${SCENARIO})
endif()
if(FMI)
  list(APPEND args --fmi ${FMI})
endif()
execute_process(COMMAND ${TWIN} ${args} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  file(WRITE ${OUT}.error "twin ${args} failed (${rc}): ${err}${out}")
  message(WARNING "twin ${args} failed (${rc}): ${err}")
endif()
file(TOUCH ${OUT}.stamp)
