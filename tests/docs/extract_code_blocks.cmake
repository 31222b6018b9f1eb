# Turns the code blocks of a Markdown file into C++ that tests/docs/docs_test.cpp compiles and
# runs (cmake -DMARKDOWN=... -DOUTPUT=... -P extract_code_blocks.cmake; run at build time, so
# editing the Markdown regenerates it).
#
#   ```cpp    blocks: each is a complete program with `int main()`. Its #include lines are
#             hoisted to the top of the output; the rest goes into `namespace doc_block_<n>`
#             behind a #line directive (compiler errors point into the Markdown), and one
#             Catch2 TEST_CASE per block runs its main() and requires 0. A block without
#             `int main()` is a configuration error: every block must be compiled AND run.
#   ```cmake  blocks: copied verbatim into kCmakeBlocks[]; the test checks each of their lines
#             against tests/package/CMakeLists.txt, the consumer project the package_consumer
#             test builds against an installed geodrift.
# Any other fenced block (```sh, ```text, ...) is an error: it would be untested.
#
# The content goes through string(FIND)/string(SUBSTRING) only, never through CMake lists,
# so the semicolons of C++ code survive.

cmake_minimum_required(VERSION 3.16)  # policies for script mode (while(TRUE), if())
if(NOT MARKDOWN OR NOT OUTPUT)
  message(FATAL_ERROR "usage: cmake -DMARKDOWN=file.md -DOUTPUT=out.inc -P ${CMAKE_CURRENT_LIST_FILE}")
endif()
file(READ "${MARKDOWN}" _md)
get_filename_component(_md_name "${MARKDOWN}" NAME)

set(_includes "")
set(_bodies "")
set(_cmake_blocks "")
set(_n 0)
set(_line 1)  # line number (1-based) of the start of _rest in the Markdown
set(_rest "${_md}")
while(TRUE)
  string(FIND "${_rest}" "```" _open)
  if(_open EQUAL -1)
    break()
  endif()
  # Line of the fence, and the info string after it.
  string(SUBSTRING "${_rest}" 0 ${_open} _before)
  string(REGEX MATCHALL "\n" _nl "${_before}")
  list(LENGTH _nl _nnl)
  math(EXPR _fence_line "${_line} + ${_nnl}")
  math(EXPR _after_ticks "${_open} + 3")
  string(SUBSTRING "${_rest}" ${_after_ticks} -1 _rest)
  string(FIND "${_rest}" "\n" _eol)
  if(_eol EQUAL -1)
    message(FATAL_ERROR "${_md_name}:${_fence_line}: unterminated code fence")
  endif()
  string(SUBSTRING "${_rest}" 0 ${_eol} _info)
  string(STRIP "${_info}" _info)
  math(EXPR _body_start "${_eol} + 1")
  string(SUBSTRING "${_rest}" ${_body_start} -1 _rest)
  # The closing fence: ``` at the start of a line.
  string(FIND "${_rest}" "\n```" _close)
  if(_close EQUAL -1)
    message(FATAL_ERROR "${_md_name}:${_fence_line}: code block is never closed")
  endif()
  math(EXPR _close_len "${_close} + 1")
  string(SUBSTRING "${_rest}" 0 ${_close_len} _code)
  math(EXPR _past "${_close} + 4")
  string(SUBSTRING "${_rest}" ${_past} -1 _rest)
  string(REGEX MATCHALL "\n" _nl "${_code}")
  list(LENGTH _nl _nnl)
  math(EXPR _line "${_fence_line} + 1 + ${_nnl}")  # the closing fence's line

  math(EXPR _first_code_line "${_fence_line} + 1")
  if(_info STREQUAL "cpp")
    math(EXPR _n "${_n} + 1")
    if(NOT _code MATCHES "int main\\(\\)")
      message(FATAL_ERROR "${_md_name}:${_fence_line}: a ```cpp block must be a whole program "
                          "with int main() (it is compiled and run by docs_tests)")
    endif()
    # Hoist the includes (they contain no semicolon, so a list of them is safe); keep the
    # line count of the body so that #line stays exact.
    string(REGEX MATCHALL "#include [<\"][^>\"\n]+[>\"]" _inc "${_code}")
    foreach(_i IN LISTS _inc)
      string(APPEND _includes "${_i}\n")
    endforeach()
    string(REGEX REPLACE "#include [<\"][^>\"\n]+[>\"]" "" _code "${_code}")
    # The TEST_CASE follows its block, with the fence's line as its location in reports.
    string(APPEND _bodies "namespace doc_block_${_n} {\n#line ${_first_code_line} \"docs/${_md_name}\"\n"
                          "${_code}}  // namespace doc_block_${_n}\n"
                          "#line ${_fence_line} \"docs/${_md_name}\"\n"
                          "TEST_CASE(\"docs/${_md_name} block ${_n} (line ${_fence_line}) runs and "
                          "returns 0\", \"[docs]\") {\n  REQUIRE(doc_block_${_n}::main() == 0);\n}\n\n")
  elseif(_info STREQUAL "cmake")
    string(APPEND _cmake_blocks
      "    {${_fence_line}, R\"geodrift_md(${_code})geodrift_md\"},\n")
  else()
    message(FATAL_ERROR "${_md_name}:${_fence_line}: code block with info string '${_info}': "
                        "only ```cpp and ```cmake blocks are allowed (both are tested)")
  endif()
endwhile()

if(_n EQUAL 0)
  message(FATAL_ERROR "${_md_name}: no ```cpp block found")
endif()

set(_out "// Generated from docs/${_md_name} by tests/docs/extract_code_blocks.cmake. Do not edit.\n\n")
string(APPEND _out "${_includes}\n${_bodies}")
string(APPEND _out "namespace doc_blocks {\n/// Number of ```cpp blocks found.\n"
                   "inline constexpr int kNumCppBlocks = ${_n};\n"
                   "/// The ```cmake blocks: Markdown line of the fence, text.\n"
                   "struct CmakeBlock {\n  int line;\n  const char* text;\n};\n"
                   "inline const CmakeBlock kCmakeBlocks[] = {\n${_cmake_blocks}"
                   "    {0, nullptr}};\n}  // namespace doc_blocks\n\n")

# Replace the output only when it changes: an edit of the Markdown's prose that moves no code
# block leaves it alone and triggers no compile (tests/docs/CMakeLists.txt uses a stamp file).
file(WRITE "${OUTPUT}.tmp" "${_out}")
execute_process(COMMAND ${CMAKE_COMMAND} -E copy_if_different "${OUTPUT}.tmp" "${OUTPUT}")
file(REMOVE "${OUTPUT}.tmp")
