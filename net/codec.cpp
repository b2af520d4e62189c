// The chunk codec (net/codec.h) arrives with issue 4.
#include "net/wire.h"
#include "net/schema/chunk_generated.h"
