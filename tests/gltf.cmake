# glTF bakes and the viewer page. Bakes: read back by a reader of the test's own (tests/gltf_check.py, against the same bake
# as PLY through OpenMesh and the scene's MTL), and through the Khronos validator from npm
# (tests/gltf_validate.sh; web/node_modules from scripts/setup.sh).
find_program(BN_PYTHON3 python3)
if(BN_PYTHON3)
  add_test(NAME gltf.cornell_readback COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/gltf_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj mm ${CMAKE_CURRENT_BINARY_DIR}/tmp/gltf_check)
  set_tests_properties(gltf.cornell_readback PROPERTIES LABELS gltf TIMEOUT 600)
  # the round trip: a glTF scene's bake under the input's own nodes (tests/gltf_tree_check.py)
  add_test(NAME gltf.round_trip_tree COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/gltf_tree_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj ${CMAKE_CURRENT_BINARY_DIR}/tmp/gltf_tree)
  set_tests_properties(gltf.round_trip_tree PROPERTIES LABELS gltf TIMEOUT 600)
  # a per-bounce bake as Blender 3.4 imports it (tests/blender_check.py; skipped without Blender)
  add_test(NAME gltf.blender_imports_every_term COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/blender_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj ${CMAKE_CURRENT_BINARY_DIR}/tmp/blender)
  set_tests_properties(gltf.blender_imports_every_term PROPERTIES LABELS gltf TIMEOUT 600 SKIP_RETURN_CODE 77)
  # gathered bakes against the furnace's exact values and the tracer at the bake's vertices
  add_test(NAME bake.gathered_against_the_tracer COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/bake_gather_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/bake_gather)
  set_tests_properties(bake.gathered_against_the_tracer PROPERTIES LABELS gltf TIMEOUT 600)
  # punctual lights in the Cornell box: the crosscheck (tests/punctual_check.py)
  add_test(NAME gltf.punctual_lights_crosscheck COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/punctual_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj ${CMAKE_CURRENT_BINARY_DIR}/tmp/punctual)
  set_tests_properties(gltf.punctual_lights_crosscheck PROPERTIES LABELS gltf TIMEOUT 600)
endif()
add_test(NAME gltf.validator COMMAND ${CMAKE_CURRENT_LIST_DIR}/gltf_validate.sh $<TARGET_FILE:bounce_cli>
  ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/gltf_validate)
set_tests_properties(gltf.validator PROPERTIES LABELS gltf TIMEOUT 900 SKIP_RETURN_CODE 77)
# The viewer page (bounce view) in headless Chromium: screenshots of L, E, KE and K2E alone checked
# against the physics (tests/view_check.py); skipped (77) where no browser is installed.
if(BN_PYTHON3)
  add_test(NAME view.cornell_in_chromium COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/view_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/view_check)
  set_tests_properties(view.cornell_in_chromium PROPERTIES LABELS gltf TIMEOUT 600 SKIP_RETURN_CODE 77)
  # The live page (bounce view --live): its worker under node against bounce solve's relit terms (dense F
  # and the hierarchy's links), --budget, bad options, and the page in headless Chromium (tests/live_check.py)
  add_test(NAME view.live COMMAND ${BN_PYTHON3} ${CMAKE_CURRENT_LIST_DIR}/live_check.py
    $<TARGET_FILE:bounce_cli> ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/tmp/live_check)
  set_tests_properties(view.live PROPERTIES LABELS gltf TIMEOUT 600 SKIP_RETURN_CODE 77)
endif()
