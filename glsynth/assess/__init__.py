"""The unified condition assessment (damage x RRDR x component) on maps from any source."""
