#pragma once
/// @file
/// The geodrift subcommands. Each takes the arguments AFTER the subcommand name (argv[0] is the
/// subcommand), prints its own --help, and returns the process exit code: 0 on success, 1 on a
/// failure of the input or the computation, 2 on a usage error. They may throw; main() turns an
/// exception into a message and exit code 1.

namespace geodrift::cli {

int run_correct(int argc, char** argv);     ///< geodrift correct (cmd_correct.cpp)
int run_eval(int argc, char** argv);        ///< geodrift eval (cmd_eval.cpp)
int run_simulate(int argc, char** argv);    ///< geodrift simulate (cmd_simulate.cpp)
int run_experiment(int argc, char** argv);  ///< geodrift experiment (cmd_experiment.cpp)
int run_geotags(int argc, char** argv);     ///< geodrift geotags build|query (cmd_geotags.cpp)
int run_render(int argc, char** argv);      ///< geodrift render (cmd_render.cpp)
int run_run(int argc, char** argv);         ///< geodrift run (cmd_run.cpp)

}  // namespace geodrift::cli
