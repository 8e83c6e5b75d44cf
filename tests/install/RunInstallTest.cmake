# cmake -DBUILD_DIR=... -DCONSUMER_DIR=... -DC_CONSUMER_DIR=... -DWORK_DIR=... -DGENERATOR=... -DCXX=... -DCC=...
#       [-DPYTHON=... -DPYTHON_DIR=...]
#       -P RunInstallTest.cmake
file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")

function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE code OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT code EQUAL 0)
    message(FATAL_ERROR "failed (${code}): ${ARGN}\n${out}\n${err}")
  endif()
  set(last_output "${out}" PARENT_SCOPE)
endfunction()

run(${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${prefix}")
if(NOT EXISTS "${prefix}/include/pmsc/PointMultiplier.h")
  message(FATAL_ERROR "install did not put the headers under ${prefix}/include/pmsc")
endif()
if(NOT EXISTS "${prefix}/include/pmsc/pmsc.h")
  message(FATAL_ERROR "install did not put the C API's header at ${prefix}/include/pmsc/pmsc.h")
endif()
if(EXISTS "${prefix}/include/examples")
  message(FATAL_ERROR "install put demo headers under ${prefix}/include/examples")
endif()
# The program, and the evaluators it lists.
run("${prefix}/bin/pmsc" evaluators)
if(NOT last_output MATCHES "\nvolume ")
  message(FATAL_ERROR "the installed pmsc does not list the volume evaluator:\n${last_output}")
endif()
# Blender as a calculation: the launcher, its scripts, and the range of motion its rig trains on.
foreach(file bin/pmsc-blender share/pmsc/blender/pmsc_blender.py share/pmsc/blender/pmsc_blender_pose.py
        share/pmsc/blender/bvh_character.py share/pmsc/blender/bvh_range_of_motion.py)
  if(NOT EXISTS "${prefix}/${file}")
    message(FATAL_ERROR "install did not put ${file} under ${prefix}")
  endif()
endforeach()
run(python3 "${prefix}/share/pmsc/blender/bvh_range_of_motion.py" --help)
run(${CMAKE_COMMAND} -S "${CONSUMER_DIR}" -B "${WORK_DIR}/consumer" -G "${GENERATOR}"
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=${CXX} -DCMAKE_PREFIX_PATH=${prefix})
run(${CMAKE_COMMAND} --build "${WORK_DIR}/consumer")
run("${WORK_DIR}/consumer/pmsc_consumer" "${WORK_DIR}/model.pmsc")
message(STATUS "${last_output}")
if(NOT last_output MATCHES "pmsc consumer: ok")
  message(FATAL_ERROR "consumer did not report ok: ${last_output}")
endif()

# The C API from a C-only project (pmsc::c), on the model the C++ consumer wrote.
run(${CMAKE_COMMAND} -S "${C_CONSUMER_DIR}" -B "${WORK_DIR}/consumer_c" -G "${GENERATOR}"
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_C_COMPILER=${CC} -DCMAKE_PREFIX_PATH=${prefix})
run(${CMAKE_COMMAND} --build "${WORK_DIR}/consumer_c")
run("${WORK_DIR}/consumer_c/pmsc_c_consumer" "${WORK_DIR}/model.pmsc")
message(STATUS "${last_output}")
if(NOT last_output MATCHES "pmsc C consumer: ok")
  message(FATAL_ERROR "C consumer did not report ok: ${last_output}")
endif()

# The Python module, when built: installed under the prefix and importable from there alone.
if(PYTHON)
  run(${CMAKE_COMMAND} -E env "PYTHONPATH=${prefix}/${PYTHON_DIR}" ${PYTHON} -c
      "import pmsc\nassert pmsc.__file__.startswith('${prefix}/'), pmsc.__file__\nprint('python module: ok', pmsc.Model.load('${WORK_DIR}/model.pmsc'))")
  message(STATUS "${last_output}")
endif()
