#pragma once
/// `arpos import-model INPUT --out MODEL.ply [options]`: converts a reference
/// body surface (mesh file, DICOM CT series folder or RTSTRUCT) into the model
/// a plan uses: a binary PLY in metres (model_import/model_import.h), and
/// reports what was detected and the model's extent, size and closedness.

#include <ostream>
#include <string>
#include <vector>

namespace arpos {

/// `args` are the words after `arpos import-model`. Prints the report to
/// stdout, errors to stderr. Returns 0 on success, 2 on a usage or input
/// error (the message names the file).
int RunImportModelCommand(const std::vector<std::string>& args);

/// The same, writing to the given streams (for tests).
int RunImportModelCommandWithOutput(const std::vector<std::string>& args, std::ostream& out,
                                    std::ostream& err);

}  // namespace arpos
