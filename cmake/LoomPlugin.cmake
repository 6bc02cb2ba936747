# loom_add_plugin(KIND material|integrator|solver NAME <name>
#                 REGISTER <file with LOOM_PLUGIN(...)>
#                 [SOURCES <implementation files>] [LIBS <libraries>] [INCLUDES <dirs>])
#
# Builds the implementation as a static library `loom_<name>` (tests link it directly) and
# the run-time module `loom_<kind>_<name>` (a CMake MODULE, loaded by dlopen) into
# LOOM_PLUGIN_OUTPUT_DIR, and installs the module into LOOM_PLUGIN_INSTALL_DIR.
function(loom_add_plugin)
  cmake_parse_arguments(P "" "KIND;NAME;REGISTER" "SOURCES;LIBS;INCLUDES" ${ARGN})
  if(NOT P_KIND OR NOT P_NAME OR NOT P_REGISTER)
    message(FATAL_ERROR "loom_add_plugin needs KIND, NAME and REGISTER")
  endif()
  if(TARGET Loom::core)
    set(_core Loom::core)
  else()
    set(_core loom_core)
  endif()
  set(_impl loom_${P_NAME})
  if(P_SOURCES)
    add_library(${_impl} STATIC ${P_SOURCES})
  else()
    add_library(${_impl} INTERFACE)
  endif()
  if(P_SOURCES)
    set_target_properties(${_impl} PROPERTIES POSITION_INDEPENDENT_CODE ON)
    target_link_libraries(${_impl} PUBLIC ${_core} ${P_LIBS})
    target_include_directories(${_impl} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR} ${P_INCLUDES})
  else()
    target_link_libraries(${_impl} INTERFACE ${_core} ${P_LIBS})
    target_include_directories(${_impl} INTERFACE ${CMAKE_CURRENT_SOURCE_DIR} ${P_INCLUDES})
  endif()
  set(_mod loom_${P_KIND}_${P_NAME})
  add_library(${_mod} MODULE ${P_REGISTER})
  target_link_libraries(${_mod} PRIVATE ${_impl})
  set_target_properties(${_mod} PROPERTIES PREFIX "" OUTPUT_NAME ${_mod}
    LIBRARY_OUTPUT_DIRECTORY ${LOOM_PLUGIN_OUTPUT_DIR}
    CXX_VISIBILITY_PRESET hidden
    INSTALL_RPATH "$ORIGIN/../..")
  install(TARGETS ${_mod} LIBRARY DESTINATION ${LOOM_PLUGIN_INSTALL_DIR})
  set_property(GLOBAL APPEND PROPERTY LOOM_PLUGIN_MODULES ${_mod})
endfunction()
