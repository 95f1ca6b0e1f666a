"""One mesh -> one library object: decomposition, Drake-loadable hulls, stable poses."""
