// One session streamed to an objdb server (`objdb stream`, `objdb eval`): a SessionHeader, then
// the dataset's frames as FLOAT32 depth (metres, exactly what the dataset reader produced) with
// RGB8 colour, while a second thread reads the server's acks and events so that the server's
// backpressure paces the writer; then EndSession, which flushes the session's map into the
// database.
#pragma once

#include <string>

#include "client/remote.h"
#include "core/io/dataset.h"
#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb::cli {

struct StreamOptions {
  Connection connection;
  std::string params_json;
  // A session of that name exists already: refuse (the server's ALREADY_EXISTS), continue it
  // after the last frame its map holds (--resume), or withdraw it and stream it again
  // (--replace).
  v1::SessionHeader::IfExists if_exists = v1::SessionHeader::IF_EXISTS_REFUSE;
  long long every = 1;
  bool end = true;
  double end_timeout_s = 600.0;
  bool verbose = false;
};

// Streams one session and prints its summary (a resumed one from the first frame after the ones
// its map holds); errors are printed as "objdb <command>: ...".
// Returns the process exit status (0, or 1 when a call or the dataset failed).
int streamSession(v1::ObjectDatabase::Stub& stub, const std::string& name, const io::Dataset& ds,
                  const StreamOptions& options, const char* command);

}  // namespace objdb::cli
