# arnav-register end to end: a case exported by 'arnav-bench register --quick --export'
# registers (rigid + non-rigid) with every output written; bad inputs exit 2 naming the
# file and line. Variables: REG (arnav-register), BENCH (arnav-bench), SRC, OUT.
file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT})
set(scene ${SRC}/data/liver/liver_coarse.scene.yaml)
execute_process(COMMAND ${BENCH} register --quick --export ${OUT}/case --out ${OUT}/bench RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "arnav-bench register --quick --export failed (${rc}): ${err}")
endif()

function(run expected_rc name)
  execute_process(COMMAND ${REG} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL expected_rc)
    message(FATAL_ERROR "${name}: expected exit ${expected_rc}, got ${rc}\nstdout: ${out}\nstderr: ${err}")
  endif()
  set(last_err "${err}" PARENT_SCOPE)
  set(last_out "${out}" PARENT_SCOPE)
endfunction()

function(expect_error pattern name)
  run(2 ${name} ${ARGN})
  if(NOT last_err MATCHES "${pattern}")
    message(FATAL_ERROR "${name}: stderr does not match '${pattern}': ${last_err}")
  endif()
endfunction()

# 1. full registration with landmarks and targets
run(0 full ${scene} --surface ${OUT}/case/surface.xyz --landmarks ${OUT}/case/landmarks.csv
    --targets ${OUT}/case/targets.csv --out ${OUT}/full --noise-mm 0.8)
foreach(f targets.csv registered_organ.obj X_IntraopModel.yaml summary.json report.txt convergence.png residuals.png)
  if(NOT EXISTS ${OUT}/full/${f})
    message(FATAL_ERROR "full: ${f} not written")
  endif()
endforeach()
file(READ ${OUT}/full/summary.json summary)
foreach(key "\"stage\": \"landmarks\"" "\"stage\": \"surface_rigid\"" "\"stage\": \"nonrigid\"" "\"deformed\": true" "\"points_trimmed\""
            "\"method\": \"loads\"" "\"basis_modes\"" "\"pose_correction_mm\"" "\"landmarks_used\": 3" "\"regularisation\"")
  if(NOT summary MATCHES "${key}")
    message(FATAL_ERROR "summary.json lacks ${key}: ${summary}")
  endif()
endforeach()
file(STRINGS ${OUT}/full/targets.csv rows)
list(LENGTH rows n)
list(GET rows 0 header)
if(NOT n EQUAL 61 OR NOT header STREQUAL "name,x_mm,y_mm,z_mm")
  message(FATAL_ERROR "targets.csv: ${n} lines, header '${header}'")
endif()
file(READ ${OUT}/full/X_IntraopModel.yaml pose)
if(NOT pose MATCHES "name: X_IntraopModel")
  message(FATAL_ERROR "X_IntraopModel.yaml: ${pose}")
endif()

# 1b. the energy method (paper 002) on the same case
run(0 energy ${scene} --surface ${OUT}/case/surface.xyz --landmarks ${OUT}/case/landmarks.csv
    --targets ${OUT}/case/targets.csv --out ${OUT}/energy --noise-mm 0.8 --method energy)
file(READ ${OUT}/energy/summary.json summary)
if(NOT summary MATCHES "\"method\": \"energy\"" OR NOT summary MATCHES "\"deformed\": true")
  message(FATAL_ERROR "energy summary: ${summary}")
endif()

# 2. rigid only, started from the pose just written
run(0 rigid ${scene} --surface ${OUT}/case/surface.xyz --initial-pose ${OUT}/full/X_IntraopModel.yaml --rigid-only --out ${OUT}/rigid)
file(READ ${OUT}/rigid/summary.json summary)
if(NOT summary MATCHES "\"initialisation\": \"initial pose\"" OR summary MATCHES "\"stage\": \"nonrigid\"")
  message(FATAL_ERROR "rigid-only summary: ${summary}")
endif()

# 3. empty cloud with landmarks: the landmark pose is kept, the non-rigid stage declines
file(WRITE ${OUT}/empty.xyz "# nothing swabbed\n")
run(0 empty ${scene} --surface ${OUT}/empty.xyz --landmarks ${OUT}/case/landmarks.csv --out ${OUT}/empty)
if(NOT last_err MATCHES "data does not support a non-rigid fit")
  message(FATAL_ERROR "empty cloud: ${last_err}")
endif()

# 4. bad inputs: exit 2, naming file and line
expect_error("empty.xyz: the cloud is empty and no landmarks" empty_alone ${scene} --surface ${OUT}/empty.xyz --out ${OUT}/x)
file(WRITE ${OUT}/nan.xyz "1 2 3\n4 5 6\n7 nan 9\n")
expect_error("nan.xyz:3: field 2 is not finite" nan ${scene} --surface ${OUT}/nan.xyz --out ${OUT}/x)
file(WRITE ${OUT}/short.csv "1,2,3\n4,5\n")
expect_error("short.csv:2: expected 3 fields" malformed ${scene} --surface ${OUT}/short.csv --out ${OUT}/x)
file(WRITE ${OUT}/metres.xyz "0.01 0.12 0.15\n0.09 0.11 0.16\n0.05 0.17 0.14\n0.07 0.13 0.19\n")
expect_error("metres.xyz: .*looks like metres.*multiply the coordinates by 1000" metres ${scene} --surface ${OUT}/metres.xyz --out ${OUT}/x)
set(lh "name,model_x,model_y,model_z,intraop_x,intraop_y,intraop_z\n")
file(WRITE ${OUT}/dup.csv "${lh}a,0,0,0,1,1,1\nb,10,0,0,11,1,1\na,0,10,0,1,11,1\n")
expect_error("dup.csv:4: landmark name 'a' appears twice" duplicate ${scene} --surface ${OUT}/case/surface.xyz --landmarks ${OUT}/dup.csv --out ${OUT}/x)
file(WRITE ${OUT}/two.csv "${lh}a,0,0,0,1,1,1\nb,10,0,0,11,1,1\n")
expect_error("two.csv: has 2 landmark\\(s\\); a rigid fit needs at least 3" too_few ${scene} --surface ${OUT}/case/surface.xyz --landmarks ${OUT}/two.csv --out ${OUT}/x)
file(WRITE ${OUT}/far.csv "name,x_mm,y_mm,z_mm\ninside,70,160,140\nfar,1000,0,0\n")
expect_error("far.csv:3: target 'far' lies outside the organ" target_outside ${scene} --surface ${OUT}/case/surface.xyz --targets ${OUT}/far.csv --out ${OUT}/x)
expect_error("cannot open" missing ${scene} --surface ${OUT}/nope.xyz --out ${OUT}/x)
run(2 usage ${scene} --out ${OUT}/x)
run(2 bad_method ${scene} --surface ${OUT}/case/surface.xyz --method magic --out ${OUT}/x)
