# arnav-sim --scalpel on the coarse liver with cutting: the cut shows in the outputs
# (more tets than the scene, cut columns in frames.csv, cut_events.csv), a scene without a
# cutting section and bad path files exit 2 naming the file and line.
file(REMOVE_RECURSE ${OUT})
execute_process(COMMAND ${EXE} ${SRC}/data/liver/liver_coarse_cut.scene.yaml --scalpel ${SRC}/data/liver/scalpel_right_lobe.csv
                        --frames 150 --every 50 --out ${OUT}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "arnav-sim --scalpel failed (${rc}): ${out} ${err}")
endif()
foreach(f frames.csv cut_events.csv volume_0000.vtk volume_0150.vtk organ_0150.vtk tumour_tumour_0150.vtk vessels_0150.vtk)
  if(NOT EXISTS ${OUT}/${f})
    message(FATAL_ERROR "arnav-sim --scalpel did not write ${f}")
  endif()
endforeach()
file(STRINGS ${OUT}/frames.csv rows)
list(GET rows 0 header)
if(NOT header MATCHES ",cutting,contact_depth_mm,topology_update_ms,model_rebuild_ms,tets,vertices,tets_cut,tets_added,pieces,events$")
  message(FATAL_ERROR "frames.csv lacks the cut columns: ${header}")
endif()
string(REGEX MATCH "\"tetrahedra\":([0-9]+)" _ "${out}")
set(before ${CMAKE_MATCH_1})
string(REGEX MATCH "\"cut\":{\"tets\":([0-9]+)" _ "${out}")
set(after ${CMAKE_MATCH_1})
if(NOT after GREATER before)
  message(FATAL_ERROR "the cut added no tets (${before} -> ${after}): ${out}")
endif()
if(NOT out MATCHES "\"healthy\":true")
  message(FATAL_ERROR "summary does not report a healthy run: ${out}")
endif()
# The organ surface of the last frame is larger than the first (cut faces).
file(READ ${OUT}/organ_0000.vtk organ0)
file(READ ${OUT}/organ_0150.vtk organ1)
string(REGEX MATCH "POLYGONS ([0-9]+)" _ "${organ0}")
set(tris0 ${CMAKE_MATCH_1})
string(REGEX MATCH "POLYGONS ([0-9]+)" _ "${organ1}")
set(tris1 ${CMAKE_MATCH_1})
if(NOT tris1 GREATER tris0)
  message(FATAL_ERROR "the organ surface has no cut faces (${tris0} -> ${tris1} triangles)")
endif()

# A scene without a cutting section.
execute_process(COMMAND ${EXE} ${SRC}/data/liver/liver_coarse.scene.yaml --scalpel ${SRC}/data/liver/scalpel_right_lobe.csv --frames 1
                RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(NOT rc EQUAL 2 OR NOT err MATCHES "has no 'cutting:' section")
  message(FATAL_ERROR "scene without cutting: expected exit 2 and a message, got ${rc}: ${err}")
endif()
# A bad path file: the line and the fix.
file(WRITE ${OUT}/bad.csv "t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z\n0,1,2,3,4,5,6\n0.5,1,2,x,4,5,6\n")
execute_process(COMMAND ${EXE} ${SRC}/data/liver/liver_coarse_cut.scene.yaml --scalpel ${OUT}/bad.csv --frames 1
                RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(NOT rc EQUAL 2 OR NOT err MATCHES "bad.csv:3: tip_z is 'x', not a number. Fix:")
  message(FATAL_ERROR "bad path: expected exit 2 naming line 3, got ${rc}: ${err}")
endif()
execute_process(COMMAND ${EXE} ${SRC}/data/liver/liver_coarse_cut.scene.yaml --scalpel ${OUT}/missing.csv --frames 1
                RESULT_VARIABLE rc ERROR_VARIABLE err OUTPUT_QUIET)
if(NOT rc EQUAL 2 OR NOT err MATCHES "missing.csv: cannot read")
  message(FATAL_ERROR "missing path: expected exit 2, got ${rc}: ${err}")
endif()
