"""tactile"""
