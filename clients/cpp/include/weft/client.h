// The weft C++ client: #include <weft/client.h> and link weft::client.
// See docs/cpp-client.md.
#pragma once

#include "weft/client/array.h"
#include "weft/client/client.h"
#include "weft/client/commands.h"
#include "weft/client/dtype.h"
#include "weft/client/module.h"
#include "weft/client/status.h"
#include "weft/client/tape.h"
#include "weft/client/types.h"
