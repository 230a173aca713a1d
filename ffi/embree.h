/* Which Embree header bindgen reads: build.rs defines ICR_EMBREE4 when embree4/rtcore.h exists. */
#ifdef ICR_EMBREE4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif
