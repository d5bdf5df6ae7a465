// Subcommands of the objdb command-line client. Each takes the arguments after "objdb"
// (argv[0] is the subcommand name) and returns the process exit status: 0 success, 1 failure,
// 2 command-line error.
#pragma once

namespace objdb {

int runHealthCommand(int argc, char** argv);  // health_command.cpp
int runFuseCommand(int argc, char** argv);    // fuse_command.cpp
int runGsmCommand(int argc, char** argv);     // gsm_command.cpp
int runSimCommand(int argc, char** argv);     // sim_command.cpp
int runInfoCommand(int argc, char** argv);    // info_command.cpp
int runSegmentCommand(int argc, char** argv); // segment_command.cpp
int runDbCommand(int argc, char** argv);      // db_command.cpp
int runIngestCommand(int argc, char** argv);  // ingest_command.cpp
int runStreamCommand(int argc, char** argv);  // stream_command.cpp
int runRemoteCommand(int argc, char** argv);  // remote_command.cpp
int runReportCommand(int argc, char** argv);  // report_command.cpp
int runEvalCommand(int argc, char** argv);    // eval_command.cpp
int runWebCommand(int argc, char** argv);     // web_command.cpp

}  // namespace objdb
