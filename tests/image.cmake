# Image and bake tests that need more than the runner: the OpenEXR C API for read-back in
# test_image, and C++ read-back through OpenImageIO and OpenMesh (tests/image_readback.cpp).
if(TARGET test_image)
  target_link_libraries(test_image PRIVATE OpenEXR::OpenEXRCore)
endif()
# Its objects are an OBJECT library that depends on nothing built here, so that the slowest file of
# the suite to compile (OpenImageIO's and OpenMesh's headers: 25 s under the sanitizers) starts with
# the first jobs instead of after bounce_cli has linked (a target's objects wait for its dependencies).
add_library(test_image_readback_obj OBJECT ${CMAKE_CURRENT_SOURCE_DIR}/image_readback.cpp)
target_include_directories(test_image_readback_obj PRIVATE ${PROJECT_SOURCE_DIR}/include ${PROJECT_SOURCE_DIR}/src)
target_include_directories(test_image_readback_obj SYSTEM PRIVATE /usr/include/OpenMesh)
target_link_libraries(test_image_readback_obj PRIVATE OpenImageIO::OpenImageIO)   # imported: its usage, no build order
target_compile_definitions(test_image_readback_obj PRIVATE BN_TEST_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
  BN_TEST_BINARY_DIR="${CMAKE_CURRENT_BINARY_DIR}/tmp/test_image_readback"
  BN_TEST_BOUNCE_EXE="$<TARGET_FILE:bounce_cli>")
add_executable(test_image_readback $<TARGET_OBJECTS:test_image_readback_obj>)
add_dependencies(test_image_readback bounce_cli)
target_link_libraries(test_image_readback PRIVATE bounce OpenImageIO::OpenImageIO OpenMeshCore m)
foreach(t exr_oiio baked_ply_openmesh png_pixels cli_previews_match_exr off_binary_openmesh)
  add_test(NAME test_image_readback.${t} COMMAND test_image_readback ${t})
  set_tests_properties(test_image_readback.${t} PROPERTIES TIMEOUT 600 LABELS test_image_readback)
endforeach()
