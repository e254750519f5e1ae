# The PyPI wheels of ROS 2 export *__rosidl_generator_py targets whose include directories
# point at the wheel build machine's Python and NumPy. Point them at this interpreter's
# instead (harmless in a normal ROS 2 workspace). Include after the find_package calls.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development.Module NumPy)
get_property(_sds_targets DIRECTORY PROPERTY IMPORTED_TARGETS)
foreach(_target IN LISTS _sds_targets)
  if(_target MATCHES "__rosidl_generator_py$")
    set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES
      "${Python3_INCLUDE_DIRS};${Python3_NumPy_INCLUDE_DIRS}")
  endif()
endforeach()
