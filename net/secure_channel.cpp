// The secure datagram channel arrives with issue 4.
#include "net/wire.h"
#include "net/schema/control_generated.h"
