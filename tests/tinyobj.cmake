# bounce's OBJ reader against tinyobjloader (an independent reader) on the shipped scenes.
find_package(tinyobjloader CONFIG QUIET)
if(tinyobjloader_FOUND)
  add_executable(test_obj_tinyobj ${CMAKE_CURRENT_LIST_DIR}/test_obj_tinyobj.cpp)
  target_include_directories(test_obj_tinyobj PRIVATE ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(test_obj_tinyobj PRIVATE bounce tinyobjloader::tinyobjloader)
  add_test(NAME obj_reader.matches_tinyobjloader COMMAND test_obj_tinyobj
    ${PROJECT_SOURCE_DIR}/meshes/cornell-box.obj ${PROJECT_SOURCE_DIR}/meshes/furnace-box.obj
    ${PROJECT_SOURCE_DIR}/../shared/data/external/mcguire-cornell/CornellBox-Original.obj)
  set_tests_properties(obj_reader.matches_tinyobjloader PROPERTIES LABELS test_scene TIMEOUT 60 SKIP_RETURN_CODE 77)
endif()
