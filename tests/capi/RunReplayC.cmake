# cmake -DPMSC=pmsc -DREPLAY_C=pmsc_capi_replay -DWORK_DIR=... -DMODE=plain|shared|regions|eps
#       -P RunReplayC.cmake
#
# Trains a model on a generated shot, replays held-out frames (some of them with motion training
# never saw, so frames hit, blend and miss) with `pmsc replay --out` and with the C API
# (replay_c.c), and checks that both outputs are the same bytes and the states the same.
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

function(run)
  execute_process(COMMAND ${ARGN} WORKING_DIRECTORY "${WORK_DIR}" RESULT_VARIABLE code
    OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT code EQUAL 0)
    message(FATAL_ERROR "failed (${code}): ${ARGN}\n${out}\n${err}")
  endif()
  set(last_output "${out}" PARENT_SCOPE)
endfunction()

# 300 frames of 24 x 24 points; the last 40 ramp in a deformer the first 200 never use.
set(shot synthetic:grid=24:frames=300:seed=1:novel=40)
run("${PMSC}" export-frames ${shot} --frames 0-199 --out train.npy --quiet)
run("${PMSC}" export-frames ${shot} --frames 200-299 --out test.npy --quiet)
set(train_options)
set(replay_options)
set(c_options)
if(MODE STREQUAL "shared")
  set(train_options --shared-channels)
elseif(MODE STREQUAL "regions")
  # The C API runs every model as a whole-frame model.
  set(train_options --regions 4)
  set(replay_options --whole-frame-fail-through)
elseif(MODE STREQUAL "eps")
  set(replay_options --eps 0.005,0.012)
  set(c_options 0.005 0.012)
elseif(NOT MODE STREQUAL "plain")
  message(FATAL_ERROR "unknown MODE '${MODE}'")
endif()
# The paper's key RMS and the largest-ratio rule: the tolerance below gives this shot hits, blends and
# misses under them. The models have sentinels (drawn in point order: the shot's values are no
# shape), which the C replay checks through pmsc_multiplier_check_sentinels as the engine does.
run("${PMSC}" train --frames train.npy --out model.pmsc --tolerance 0.05 --calibration max --key-error rms
  --quiet ${train_options})
run("${PMSC}" replay --model model.pmsc --frames test.npy --report report.json --out pmsc_out.npy
    --quiet ${replay_options})
run("${REPLAY_C}" model.pmsc test.npy c_out.npy ${c_options})
set(c_states "${last_output}")

execute_process(COMMAND ${CMAKE_COMMAND} -E compare_files pmsc_out.npy c_out.npy
  WORKING_DIRECTORY "${WORK_DIR}" RESULT_VARIABLE differ)
if(NOT differ EQUAL 0)
  message(FATAL_ERROR "${WORK_DIR}: pmsc_out.npy (pmsc replay) and c_out.npy (the C API) differ")
endif()

file(READ "${WORK_DIR}/report.json" report)
if(MODE STREQUAL "regions")
  string(JSON regions GET "${report}" summary regions)
  if(NOT regions EQUAL 4)
    message(FATAL_ERROR "the model has ${regions} regions, expected 4")
  endif()
endif()
string(JSON frames LENGTH "${report}" frames)
string(REGEX REPLACE "\n$" "" c_states "${c_states}")
string(REPLACE "\n" ";" c_states "${c_states}")
list(LENGTH c_states c_frames)
if(NOT c_frames EQUAL frames)
  message(FATAL_ERROR "the C replay printed ${c_frames} states for ${frames} frames")
endif()
set(counts_hit 0)
set(counts_blend 0)
set(counts_miss 0)
math(EXPR last "${frames} - 1")
foreach(i RANGE ${last})
  string(JSON state GET "${report}" frames ${i} state)
  list(GET c_states ${i} c_state)
  if(NOT state STREQUAL c_state)
    message(FATAL_ERROR "frame ${i}: pmsc replay says ${state}, the C API ${c_state}")
  endif()
  math(EXPR counts_${state} "${counts_${state}} + 1")
endforeach()
message(STATUS "${frames} frames, the same bytes and states: ${counts_hit} hit, ${counts_blend} blend, "
  "${counts_miss} miss")
# The shot is chosen so that every path of the soft cache is compared.
if(counts_hit EQUAL 0 OR counts_blend EQUAL 0 OR counts_miss EQUAL 0)
  message(FATAL_ERROR "the shot no longer gives hits, blends and misses: choose another --tolerance")
endif()
