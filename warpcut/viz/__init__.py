"""warpcut/viz"""
