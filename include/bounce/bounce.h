/* bounce: the whole public API (one header per module, all C with extern "C" guards). */
#ifndef BOUNCE_BOUNCE_H
#define BOUNCE_BOUNCE_H

#include "bounce/status.h"
#include "bounce/layers.h"
#include "bounce/scene.h"
#include "bounce/rt.h"
#include "bounce/transport.h"
#include "bounce/formfactor.h"
#include "bounce/solve.h"
#include "bounce/image.h"
#include "bounce/gather.h"
#include "bounce/bake.h"
#include "bounce/trace.h"
#include "bounce/study.h"
#include "bounce/pipeline.h"
#include "bounce/flat.h"
#include "bounce/dist.h"

#endif
